"""The joint optimisation by differentiable rendering, on the painted plane of the refinement tests: rendered
against the images, a mesh whose attributes start wrong takes the paint's colour and class, and one whose surface
starts too high comes down."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.config import JointConfig
from cama_pipeline.surface.joint import render_optimise
from cama_pipeline.surface.optimise import observe
from tests.surface.painted_plane import CONFIG, mesh_at, paint, scene

JOINT = JointConfig(epochs=12, images_per_batch=4, rays_per_image=2048)


def painted_truth(mesh_xy: np.ndarray) -> np.ndarray:
    return paint(mesh_xy[:, 0], mesh_xy[:, 1], painted=True)


def seen_middle(mesh_xy: np.ndarray) -> np.ndarray:
    """The patch's middle, which cameras on every side see."""
    return (mesh_xy[:, 0] > 2) & (mesh_xy[:, 0] < 10) & (mesh_xy[:, 1] > 2) & (mesh_xy[:, 1] < 10)


def test_wrong_colours_and_classes_are_rendered_into_the_images_and_corrected() -> None:
    views, dataset = scene(painted=True)
    config = replace(
        CONFIG, joint=replace(JOINT, height_lr=0.0, vertex_height_lr=0.0, colour_lr=0.05, semantic_lr=0.2)
    )
    mesh = mesh_at(0.0, config)
    vertices = len(mesh.vertex_xy)
    mesh.colour = torch.full((vertices, 3), 0.5)
    mesh.logits = torch.zeros((vertices, 5))
    mesh.logits[:, int(Semantic.ROAD)] = 1.0  # everything road, paint included
    mesh.step = torch.zeros(vertices)
    history = render_optimise(mesh, dataset, views, config, lambda images, loss: None)
    assert len(history) == 12 and history[-1]["loss"] < history[0]["loss"]
    assert 0.5 < history[0]["rays_hitting"] <= 1.0
    xy = mesh.vertex_xy.numpy()
    middle, truth = seen_middle(xy), painted_truth(xy)
    marked = mesh.logits.argmax(dim=1).numpy() == int(Semantic.LANE_MARKING)
    agree = (marked == truth)[middle].mean()
    assert agree > 0.9  # from 1 - paint share (about 0.8) when all is road
    grey = mesh.colour.numpy().mean(axis=1) * 255
    assert np.median(grey[middle & truth]) > 190 and np.median(grey[middle & ~truth]) < 110


def test_a_surface_seen_too_high_is_pulled_down_towards_the_painted_plane() -> None:
    views, dataset = scene(painted=True)
    config = replace(CONFIG, joint=replace(JOINT, height_lr=0.01, colour_lr=0.02, semantic_lr=0.0))
    mesh = mesh_at(0.04, config)
    observe(mesh, dataset, views, config, lambda images, loss: None)
    render_optimise(mesh, dataset, views, config, lambda images, loss: None)
    middle = seen_middle(mesh.vertex_xy.numpy())
    with torch.no_grad():
        heights = (mesh.control.at_vertices(mesh.control_heights()) + mesh.residual).numpy()
    # measured 0.012 after 12 passes: gradient descent on the colour error converges slowly (the plane sweep of
    # `refine` brings the same plane under 0.008 in one pass)
    assert float(np.median(heights[middle])) < 0.02  # from 0.04


def test_no_epochs_is_no_pass_and_no_change() -> None:
    views, dataset = scene(painted=True)
    config = replace(CONFIG, joint=JointConfig(epochs=0))
    mesh = mesh_at(0.0, config)
    observe(mesh, dataset, views, config, lambda images, loss: None)
    colour = mesh.colour.clone()
    assert render_optimise(mesh, dataset, views, config, lambda images, loss: None) == []
    assert torch.equal(mesh.colour, colour) and float(mesh.residual.abs().max()) == 0.0


@pytest.mark.parametrize(
    ("field", "value"),
    [("epochs", -1), ("rays_per_image", 0), ("samples", 1), ("height_lr", -0.1), ("search_m", (-0.1, 0.3))],
)
def test_bad_joint_settings_are_named(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"JointConfig.{field}"):
        JointConfig(**{field: value})  # type: ignore[arg-type]
