"""The viser scene of the 3D review: layers with toggles, vectors kept in step with their source, click to select.

`ReviewScene` owns the scene nodes; `apply_changes` draws a source's changes and `sync_vectors` a whole set, each
redrawing only elements whose id, version, state or class changed, so polling a source every few seconds is cheap.
"""

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
import viser
from trimesh.visual.color import ColorVisuals
from trimesh.visual.material import PBRMaterial
from trimesh.visual.texture import TextureVisuals

from app.viewer.content import SparsePointsView, Surface, lift_polyline
from app.viewer.geometry import LocalFrame, pick_element, polyline_segments
from app.viewer.sources import VectorChanges, ViewElement
from app.viewer.style import CAMERA_RGB, SELECTED_RGB, element_rgb

logger = logging.getLogger(__name__)

VECTOR_LIFT_M = 0.05
"""Vectors are drawn this far above the surface so the mesh does not hide them."""
PICK_DISTANCE_M = 1.5


@dataclass(frozen=True)
class SyncCounts:
    """What one `sync_vectors` call did."""

    added: int
    updated: int
    removed: int
    not_lifted: int


def matte(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy of a vertex-coloured mesh that viser shows in its own colours: a rough, non-metallic material
    (a glTF mesh without one is drawn as metal, which mirrors viser's bright sky) and the sRGB colours made
    linear, as glTF vertex colours are. A textured mesh is returned as it is."""
    if not isinstance(mesh.visual, ColorVisuals):
        return mesh
    srgb = np.asarray(mesh.visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    colors = np.column_stack([np.round(linear * 255), np.full(len(srgb), 255)]).astype(np.uint8)
    material = PBRMaterial(
        baseColorFactor=[255, 255, 255, 255], metallicFactor=0.0, roughnessFactor=1.0, doubleSided=True
    )
    copy = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)
    copy.visual = TextureVisuals(material=material)
    copy.visual.vertex_attributes["color"] = colors
    return copy


class ReviewScene:
    """The 3D review scene on a viser server."""

    def __init__(self, server: viser.ViserServer, frame: LocalFrame, surface: Surface) -> None:
        self.server = server
        self.frame = frame
        self.surface = surface
        self._vectors: dict[str, tuple[ViewElement, np.ndarray]] = {}
        self._handles: dict[str, viser.SceneNodeHandle] = {}
        self.selected: str | None = None
        self._select_listeners: list[Callable[[str | None], None]] = []
        self._panel = server.gui.add_markdown("Click a vector to see its id and state.")
        self._toggles: dict[str, viser.GuiCheckboxHandle] = {}
        server.scene.on_click()(self._on_click)

    def _toggle(self, layer: str, nodes: Sequence[viser.SceneNodeHandle]) -> None:
        """A checkbox that shows or hides a layer's nodes."""
        box = self.server.gui.add_checkbox(layer, initial_value=True)

        @box.on_update
        def _(_event: object) -> None:
            for node in nodes:
                node.visible = box.value

        self._toggles[layer] = box

    def add_mesh(self, mesh: trimesh.Trimesh) -> None:
        """The road mesh with its vertex colours (as a matte surface)."""
        handle = self.server.scene.add_mesh_trimesh("/surface/mesh", matte(mesh))
        self._toggle("Road mesh", [handle])

    def add_cameras(self, segments: np.ndarray) -> None:
        """All keyframe frustums as one line-segment node."""
        handle = self.server.scene.add_line_segments(
            "/cameras", segments.astype(np.float32), CAMERA_RGB, thickness=1.5, thickness_units="screen"
        )
        self._toggle(f"Cameras ({len(segments) // 8})", [handle])

    def add_points(self, points: SparsePointsView) -> None:
        """The sparse SfM points coloured by semantic label."""
        handle = self.server.scene.add_point_cloud(
            "/sparse_points", points.xyz.astype(np.float32), points.rgb, point_size=0.08, precision="float32"
        )
        self._toggle(f"Sparse points ({len(points.xyz)})", [handle])

    def add_vector_toggle(self) -> None:
        """One checkbox for all vectors (present and future)."""
        box = self.server.gui.add_checkbox("Vectors", initial_value=True)

        @box.on_update
        def _(_event: object) -> None:
            for handle in self._handles.values():
                handle.visible = box.value

        self._toggles["Vectors"] = box

    def _draw(self, element: ViewElement, points: np.ndarray) -> None:
        rgb = SELECTED_RGB if element.id == self.selected else element_rgb(element.cls, element.state)
        lifted = points + np.array([0.0, 0.0, VECTOR_LIFT_M])
        segments = polyline_segments(lifted, closed=element.closed).astype(np.float32)
        box = self._toggles.get("Vectors")
        self._handles[element.id] = self.server.scene.add_line_segments(
            f"/vectors/{element.id}",
            segments,
            rgb,
            thickness=4.0 if element.id == self.selected else 2.5,
            thickness_units="screen",
            visible=box.value if box is not None else True,
        )

    def sync_vectors(self, elements: Sequence[ViewElement]) -> SyncCounts:
        """Make the drawn vectors equal `elements`; only changed ones are redrawn."""
        incoming = {e.id: e for e in elements}
        gone = [i for i in self._vectors if i not in incoming]
        return self.apply_changes(VectorChanges(list(incoming.values()), gone))

    def apply_changes(self, changes: VectorChanges) -> SyncCounts:
        """Remove the elements gone and draw the new or changed ones (all others stay as drawn, unless the
        changes are `complete`); an element whose version, state and class are the ones drawn is left alone."""
        if changes.complete:
            return self.sync_vectors(changes.elements)
        removed = [i for i in dict.fromkeys(changes.removed) if i in self._vectors]
        for element_id in removed:
            self._handles.pop(element_id).remove()
            del self._vectors[element_id]
        added = updated = not_lifted = 0
        redrawn: set[str] = set()
        for element in changes.elements:
            known = self._vectors.get(element.id)
            if known is not None and known[0].key == element.key:
                continue
            points = lift_polyline(element.points_xy, self.surface, self.frame)
            if points is None:
                not_lifted += 1
                continue
            added, updated = (added + 1, updated) if known is None else (added, updated + 1)
            self._vectors[element.id] = (element, points)
            self._draw(element, points)
            redrawn.add(element.id)
        if self.selected is not None and self.selected not in self._vectors:
            self.select(None)
        elif self.selected in redrawn:
            self._notify()  # the selected element changed: whoever shows more of it redraws
        return SyncCounts(added, updated, len(removed), not_lifted)

    def select(self, element_id: str | None) -> None:
        """Highlight an element and show its id, class, state and version in the panel."""
        previous, self.selected = self.selected, element_id
        for redraw in {previous, element_id} - {None}:
            if redraw in self._vectors:
                self._draw(*self._vectors[redraw])
        if element_id is None:
            self._panel.content = "Click a vector to see its id and state."
            self._notify()
            return
        element = self._vectors[element_id][0]
        self._panel.content = f"**Element {element.id}**  \nclass: {element.cls}  \nstate: {element.state}  \nversion: {element.version}"
        self._notify()

    def on_select(self, callback: Callable[[str | None], None]) -> None:
        """Call `callback(element_id)` after each selection (None: nothing selected) and after the selected
        element changed in its source (e.g. app/viewer/cameras.py shows its camera views)."""
        self._select_listeners.append(callback)

    def _notify(self) -> None:
        for callback in self._select_listeners:
            callback(self.selected)

    def element_centre(self, element_id: str) -> np.ndarray | None:
        """The view-frame centre of a drawn element (its lifted vertices' mean); None when not drawn."""
        known = self._vectors.get(element_id)
        return None if known is None else known[1].mean(axis=0)

    def pick(self, ray_origin: np.ndarray, ray_direction: np.ndarray) -> str | None:
        """The drawn element nearest to a view-frame ray, if any is close enough."""
        polylines = {element_id: points for element_id, (_, points) in self._vectors.items()}
        return pick_element(polylines, ray_origin, ray_direction, max_distance_m=PICK_DISTANCE_M)

    def _on_click(self, event: viser.SceneClickEvent) -> None:
        self.select(self.pick(np.asarray(event.ray_origin), np.asarray(event.ray_direction)))
