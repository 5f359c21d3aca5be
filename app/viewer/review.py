"""Open a site in the 3D review: read its files, fill a `ReviewScene`, keep the vectors in step with a source, and
(for a backend source) show the selected element's camera views."""

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import viser

from app.viewer.cameras import attach_camera_views
from app.viewer.content import (
    camera_segments,
    first_site,
    keyframe_cameras,
    load_surface,
    local_frame_of,
    road_mesh,
    sparse_points,
    surface_folder,
)
from app.viewer.focus import focus_on_connect
from app.viewer.scene import ReviewScene
from app.viewer.sources import VectorSource, VectorSourceError

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ViewInputs:
    """Which site to show and from where."""

    site_dir: Path
    """A site folder written by `cama synth` (its data set is `nuscenes/` inside)."""
    workspace: Path
    site_id: str | None
    """The workspace's site to show; None: its first site (`sites/index.json`)."""
    max_mesh_faces: int = 300_000
    frustum_depth_m: float = 1.0


def open_review(server: viser.ViserServer, inputs: ViewInputs, source: VectorSource) -> ReviewScene:
    """Build every layer of the site's 3D review on `server` and draw the source's current vectors."""
    site_id = inputs.site_id or first_site(inputs.workspace)
    folder, reconstructed = surface_folder(inputs.site_dir, inputs.workspace, site_id)
    surface = load_surface(folder, reconstructed=reconstructed)
    frame = local_frame_of(surface)
    scene = ReviewScene(server, frame, surface)
    scene.add_mesh(road_mesh(inputs.workspace, site_id, surface, frame, max_faces=inputs.max_mesh_faces))
    views = keyframe_cameras(inputs.site_dir / "nuscenes", inputs.workspace, site_id)
    scene.add_cameras(camera_segments(views, frame, depth_m=inputs.frustum_depth_m))
    points = sparse_points(inputs.workspace, site_id, frame)
    if points is None:
        logger.info("no sparse points yet (run `cama sfm`)")
    else:
        scene.add_points(points)
    show_vectors(scene, source)
    attach_camera_views(scene, source)
    return scene


def show_vectors(scene: ReviewScene, source: VectorSource) -> ReviewScene:
    """Draw the source's vectors (with their toggle) and focus each new browser on the element its link names."""
    scene.add_vector_toggle()
    counts = scene.sync_vectors(source.load())
    logger.info("%d vectors drawn, %d without elevation", counts.added, counts.not_lifted)
    scene.server.on_client_connect(focus_on_connect(scene))
    return scene


def follow(scene: ReviewScene, source: VectorSource, stop: threading.Event, *, interval_s: float) -> None:
    """Ask the source what changed every `interval_s` until `stop` is set and draw that; a failed read keeps the
    last state and warns."""
    while not stop.wait(interval_s):
        try:
            counts = scene.apply_changes(source.changes())
        except VectorSourceError as err:
            logger.warning("vectors not refreshed: %s", err)
            continue
        if counts.added or counts.updated or counts.removed:
            logger.info(
                "vectors: %d added, %d updated, %d removed", counts.added, counts.updated, counts.removed
            )


def _wait_for(source: VectorSource, timeout_s: float, stop: threading.Event) -> bool:
    """Whether the source answers within `timeout_s` (e.g. a backend still starting)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not stop.is_set():
        try:
            source.load()
            return True
        except VectorSourceError:
            stop.wait(1.0)
    return False


def serve_in_background(
    inputs: ViewInputs,
    source: VectorSource,
    *,
    host: str,
    port: int,
    interval_s: float = 2.0,
    wait_s: float = 120.0,
) -> threading.Event:
    """Serve the 3D review from a daemon thread once the source answers; set the returned event to stop it."""
    stop = threading.Event()

    def serve() -> None:
        if not _wait_for(source, wait_s, stop):
            logger.error("3D review not started: the vector source did not answer within %.0f s", wait_s)
            return
        server = viser.ViserServer(host=host, port=port, label="CAMA Studio 3D review", verbose=False)
        try:
            follow(open_review(server, inputs, source), source, stop, interval_s=interval_s)
        except (ValueError, OSError) as err:
            logger.error("3D review stopped: %s", err)
        finally:
            server.stop()

    threading.Thread(target=serve, name="cama-3d-review", daemon=True).start()
    return stop
