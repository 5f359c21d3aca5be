"""Curb labels: voted at curb height off the road, a raised curb seen obliquely lands in place."""

from dataclasses import dataclass, replace

import numpy as np
import torch

from cama_pipeline.cameras import CameraView
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.elevation import new_elevation_mlp
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.labels import fused_logits
from cama_pipeline.surface.optimise import new_mesh, observe

CAMERA_HEIGHT_M, CURB_LINE_Y, CURB_WIDTH_M, CURB_HEIGHT_M = 1.5, 5.0, 0.2, 0.13
WIDTH, HEIGHT, FOCAL_PX, PITCH_RAD = 320, 240, 300.0, 0.35


def test_cells_take_the_height_at_which_their_views_agree_more() -> None:
    # classes: background, road, curb, marking, crosswalk
    ground = torch.tensor(
        [[0.2, 0.1, 0.7, 0, 0], [0.05, 0.9, 0.05, 0, 0], [0.2, 0.6, 0.2, 0, 0], [0.3, 0, 0.7, 0, 0]]
    )
    raised = torch.tensor(
        [[0.9, 0.0, 0.1, 0, 0], [0.5, 0.0, 0.5, 0, 0], [0.1, 0.0, 0.9, 0, 0], [0.0, 1.0, 0.0, 0, 0]]
    )
    # off road at road level: the raised vote; road agreed on: road; a curb top seen as the face's foot:
    # curb; curb height never gives a road class
    assert fused_logits(ground, raised).argmax(dim=1).tolist() == [0, 1, 2, 2]
    assert fused_logits(ground, None).argmax(dim=1).tolist() == [2, 1, 1, 2]
    assert fused_logits(2 * ground, 7 * raised).argmax(dim=1).tolist() == [0, 1, 2, 2]  # votes, not shares


def scene_label(direction: np.ndarray, centre: np.ndarray, foot_road: bool) -> int:
    """The class a ray hits: road (z = 0, y < curb line), the curb face and top (0.2 m), sidewalk beyond;
    `foot_road`: the face's lower half is labelled road (as the rendered masks do: the step is a ramp)."""
    if direction[2] >= 0:
        return int(Semantic.SKY)
    to_road = -centre[2] / direction[2]
    if centre[1] + to_road * direction[1] < CURB_LINE_Y:
        return int(Semantic.ROAD)
    to_face = (CURB_LINE_Y - centre[1]) / direction[1]
    face_z = centre[2] + to_face * direction[2]
    if face_z <= CURB_HEIGHT_M:
        return int(Semantic.ROAD if foot_road and face_z < CURB_HEIGHT_M / 2 else Semantic.CURB)
    to_top = (CURB_HEIGHT_M - centre[2]) / direction[2]
    top_y = centre[1] + to_top * direction[1]
    return int(Semantic.CURB if top_y < CURB_LINE_Y + CURB_WIDTH_M else Semantic.BACKGROUND)


def oblique_view(y: float = 0.0, foot_road: bool = False) -> tuple[CameraView, np.ndarray]:
    """A camera 1.5 m above the road at (0, y), looking along +y pitched down, and its ray-cast mask."""
    forward = np.array([0.0, np.cos(PITCH_RAD), -np.sin(PITCH_RAD)])
    right = np.array([1.0, 0.0, 0.0])
    world_from_cam = np.eye(4)
    world_from_cam[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])
    world_from_cam[:3, 3] = [0.0, y, CAMERA_HEIGHT_M]
    K = np.array([[FOCAL_PX, 0, (WIDTH - 1) / 2], [0, FOCAL_PX, (HEIGHT - 1) / 2], [0, 0, 1]])
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH]
    rays = np.stack([(u - K[0, 2]) / FOCAL_PX, (v - K[1, 2]) / FOCAL_PX, np.ones_like(u, float)], -1)
    world_rays = rays @ world_from_cam[:3, :3].T
    centre = world_from_cam[:3, 3]
    mask = np.array([[scene_label(d, centre, foot_road) for d in row] for row in world_rays], np.uint8)
    view = CameraView(f"{y}", f"{y}", "scene", "CAM", 0, 0, world_from_cam, np.eye(4), K, WIDTH, HEIGHT)
    return view, mask


@dataclass(frozen=True)
class FakeImage:
    semantic: np.ndarray

    def load_rgb(self) -> np.ndarray:
        return np.full((*self.semantic.shape, 3), 128, np.uint8)

    def load_semantic(self) -> np.ndarray:
        return self.semantic


@dataclass(frozen=True)
class FakeDataset:
    masks: dict[str, np.ndarray]

    def image(self, token: str) -> FakeImage:
        return FakeImage(self.masks[token])


def curb_rows_y(
    curb_height_m: float,
    camera_ys: tuple[float, ...] = (0.0,),
    foot_road: bool = False,
    kerb_line: bool = False,
) -> np.ndarray:
    """y of the grid rows (x = 0 column) labelled curb after observing oblique views from `camera_ys`; the two
    class votes alone unless `kerb_line` (`steps.beyond_kerb_line`)."""
    config = SurfaceConfig(resolution_m=0.05, control_spacing_m=0.5, curb_height_m=curb_height_m)
    config = replace(config, kerb_step=replace(config.kerb_step, kerb_line=kerb_line))
    rows, cols = 81, 21  # y 8 .. 4, x -0.5 .. 0.5
    grid = SurfaceGrid((-0.5, 8.0), 0.05, rows, cols, np.arange(rows * cols).reshape(rows, cols))
    mlp = new_elevation_mlp(grid, np.zeros(1), config)
    with torch.no_grad():
        mlp.net[-1].weight.zero_()
        mlp.net[-1].bias.zero_()
    mesh = new_mesh(grid, mlp, config, torch.device("cpu"))
    views, masks = zip(*(oblique_view(y, foot_road) for y in camera_ys), strict=True)
    dataset = FakeDataset({view.token: mask for view, mask in zip(views, masks, strict=True)})
    observe(mesh, dataset, list(views), config, lambda done, loss: None)  # type: ignore[arg-type]
    labels = mesh.logits.argmax(dim=1).numpy().reshape(rows, cols)[:, cols // 2]
    return grid.xy_of_cells(np.arange(rows), np.zeros(rows, int))[labels == int(Semantic.CURB), 1]


def test_a_raised_curb_is_labelled_in_place_not_smeared_beyond() -> None:
    placed = curb_rows_y(CURB_HEIGHT_M)
    smeared = curb_rows_y(0.0)
    truth = (CURB_LINE_Y - 0.03, CURB_LINE_Y + CURB_WIDTH_M + 0.03)
    assert len(placed) and placed.min() >= truth[0] and placed.max() <= truth[1]
    assert len(placed) >= 3  # about the 0.2 m strip at 0.05 m
    assert smeared.max() > CURB_LINE_Y + 2 * CURB_WIDTH_M  # at road level the curb spreads over the sidewalk


def test_with_the_faces_foot_labelled_road_several_views_still_place_the_curb_top() -> None:
    # the cells next to the curb line are road at road level and curb at curb height from every view (a
    # tie, road kept); the rest of the top is placed, and nothing beyond it
    placed = curb_rows_y(CURB_HEIGHT_M, (0.0, 1.5, 3.0), foot_road=True)
    truth = (CURB_LINE_Y - 0.03, CURB_LINE_Y + CURB_WIDTH_M + 0.03)
    assert len(placed) >= 3 and placed.min() >= truth[0] and placed.max() <= truth[1]


def test_the_kerb_line_places_the_curb_top_where_the_vote_alone_leaves_its_edge_road() -> None:
    truth = (CURB_LINE_Y - 0.03, CURB_LINE_Y + CURB_WIDTH_M + 0.03)
    # the face's foot labelled road, as the rendered masks do: the votes alone leave the first curb rows road
    # (one view: every row), the kerb line takes exactly the curb top
    for views in ((0.0,), (0.0, 1.5, 3.0)):
        alone = curb_rows_y(CURB_HEIGHT_M, views, foot_road=True)
        placed = curb_rows_y(CURB_HEIGHT_M, views, foot_road=True, kerb_line=True)
        assert len(placed) == 5 and placed.min() >= truth[0] and placed.max() <= truth[1]
        assert len(alone) < len(placed)
    # the whole face labelled curb: a road cell read at curb height sees the face from every view, so on both
    # sides of the line one vote of two says road, and the 0.1 m smoothing takes up to three 0.05 m road rows
    # before the kerb (README, "The kerb line of the two votes")
    placed = curb_rows_y(CURB_HEIGHT_M, (0.0,), kerb_line=True)
    assert placed.max() <= truth[1] and CURB_LINE_Y - 0.16 <= placed.min() < truth[0]
