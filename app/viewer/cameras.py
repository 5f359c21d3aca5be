"""Camera views of the selected element in the 3D review (issue 25): the key-frame images that see it best, each
drawn as a frustum at the image's SfM pose with the image on it, and the element as the backend lifts it through
the site's elevation (the 3D line the editor's camera panel projects), drawn bright.

Everything comes from the backend's camera endpoints (app/backend/api/routes/cameras.py) through the review's
`ApiVectorSource`, so the 3D review shows the same views, poses and lifted element as the editor. A site without
posed images shows the backend's notice instead. The views of a file source's elements cannot be asked for (their
ids are not the backend's), so `cama view` without `--api` has no camera views.

Frames: the backend speaks site coordinates (global minus the site origin in x and y, z global); the review draws
in its local frame (global minus `LocalFrame.origin`), so a site point p is drawn at p + offset with
offset = (origin_x, origin_y, 0) - frame.origin. A camera's `cam_from_site` maps site points into the OpenCV
camera frame (x right, y down, z forward), the convention of viser's frustums, so the frustum's pose is its
inverse: rotation R^T, position the camera centre -R^T t.
"""

import logging
import threading
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import viser
import viser.transforms as vtf

from app.viewer.geometry import polyline_segments
from app.viewer.scene import ReviewScene
from app.viewer.sources import ApiVectorSource, VectorSourceError
from app.viewer.style import LIFTED_ELEMENT_RGB, VIEW_FRUSTUM_RGB

logger = logging.getLogger(__name__)

DEFAULT_VIEWS = 4
"""Views shown per element at first (the GUI slider offers 2..6, the backend's range)."""
IMAGE_WIDTH = 320
"""Width of the images put on the frusta (one of the backend's widths): enough to recognise the scene."""
FRUSTUM_DEPTH_M = 3.0
"""Distance from a frustum's apex to its image."""
ELEMENT_LIFT_M = 0.08
"""The lifted element is drawn this far above its 3D line, over the surface and the plain vector."""
HINT = "Select a vector to see the camera images that see it."


@dataclass(frozen=True, eq=False)
class PosedCamera:
    """One image's pinhole camera as the backend gives it (`GET /images/{token}/camera`)."""

    token: str
    width: int
    height: int
    intrinsic: np.ndarray
    """3x3 K in full-resolution pixels."""
    cam_from_site: np.ndarray
    """4x4 rigid map from site coordinates into the camera frame (x right, y down, z forward)."""

    @classmethod
    def from_json(cls, token: str, body: dict[str, Any]) -> "PosedCamera":
        """Read the endpoint's answer; VectorSourceError naming the token when it is malformed."""
        try:
            intrinsic = np.asarray(body["K"], dtype=np.float64).reshape(3, 3)
            cam_from_site = np.asarray(body["cam_from_site"], dtype=np.float64).reshape(4, 4)
            width, height = int(body["width"]), int(body["height"])
        except (KeyError, TypeError, ValueError) as err:
            raise VectorSourceError(f"image {token}: malformed camera parameters: {err}") from None
        if width <= 0 or height <= 0 or intrinsic[1, 1] <= 0:
            raise VectorSourceError(
                f"image {token}: malformed camera parameters: {width}x{height}, K={body['K']}"
            )
        return cls(token, width, height, intrinsic, cam_from_site)

    @property
    def site_from_cam(self) -> np.ndarray:
        """4x4 inverse of `cam_from_site`: the camera's axes and centre in site coordinates."""
        rotation, translation = self.cam_from_site[:3, :3], self.cam_from_site[:3, 3]
        inverse = np.eye(4)
        inverse[:3, :3] = rotation.T
        inverse[:3, 3] = -rotation.T @ translation
        return inverse

    @property
    def fov_y(self) -> float:
        """Vertical field of view in radians (viser's `fov`)."""
        return float(2.0 * np.arctan2(self.height / 2.0, self.intrinsic[1, 1]))

    @property
    def aspect(self) -> float:
        """Width over height."""
        return self.width / self.height


def frustum_pose(camera: PosedCamera, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(wxyz, position) of the camera's frustum in the review's frame (site point p drawn at p + offset)."""
    site_from_cam = camera.site_from_cam
    wxyz = vtf.SO3.from_matrix(site_from_cam[:3, :3]).wxyz
    return np.asarray(wxyz, dtype=np.float64), site_from_cam[:3, 3] + offset


def decode_jpeg(token: str, data: bytes) -> np.ndarray:
    """(H, W, 3) uint8 RGB of an image the backend served; VectorSourceError when it is not an image."""
    bgr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise VectorSourceError(f"image {token}: the backend's answer is not an image")
    return np.ascontiguousarray(bgr[:, :, ::-1])


@dataclass(frozen=True, eq=False)
class ElementViews:
    """What the backend says about one element's best views."""

    views: list[dict[str, Any]]
    """The `/views` entries (token, channel, station_m, ...), in station order."""
    cameras: list[PosedCamera]
    images: list[np.ndarray]
    points_3d: np.ndarray
    """(N, 3) the element lifted by the backend, site metres; empty when no view sees it."""
    notice: str | None


def fetch_views(api: ApiVectorSource, element_id: str, n: int) -> ElementViews:
    """The element's n best views with their cameras, images (IMAGE_WIDTH wide) and its lifted 3D line."""
    site = f"/api/sites/{api.site_id}"
    answer = api.get(f"{site}/views", element_id=element_id, n=n).json()
    views = list(answer["views"])
    cameras, images = [], []
    for view in views:
        token = str(view["token"])
        cameras.append(PosedCamera.from_json(token, api.get(f"{site}/images/{token}/camera").json()))
        images.append(decode_jpeg(token, api.get(f"{site}/images/{token}", width=IMAGE_WIDTH).content))
    points = np.zeros((0, 3))
    if views:
        projection = api.get(f"{site}/elements/{element_id}/projection", image=views[0]["token"]).json()
        points = np.asarray(projection["points_3d"], dtype=np.float64).reshape(-1, 3)
    return ElementViews(views, cameras, images, points, answer.get("notice"))


class CameraViews:
    """The "Camera views" GUI folder (notice, number of views, show/hide) and the frusta of the selected
    element, redrawn on each selection."""

    def __init__(self, scene: ReviewScene, api: ApiVectorSource) -> None:
        self.scene = scene
        self.api = api
        self.offset = np.append(api.site_origin_xy, 0.0) - scene.frame.origin
        """Site coordinates -> the review's frame."""
        self.frusta: list[viser.CameraFrustumHandle] = []
        self._nodes: list[viser.SceneNodeHandle] = []
        self._lock = threading.Lock()
        self._status_notice: str | None = None
        gui = scene.server.gui
        with gui.add_folder("Camera views"):
            self.notice = gui.add_markdown(HINT)
            self.count = gui.add_slider("Views", min=2, max=6, step=1, initial_value=DEFAULT_VIEWS)
            self.shown = gui.add_checkbox("Show camera views", initial_value=True)
        self.count.on_update(lambda _event: self.show(self.scene.selected))
        self.shown.on_update(lambda _event: self._set_visible(self.shown.value))
        self._check_status()
        scene.on_select(self.show)

    def _check_status(self) -> bool:
        """Whether the site has posed images (`GET /cameras`); otherwise its notice is shown."""
        try:
            status = self.api.get(f"/api/sites/{self.api.site_id}/cameras").json()
        except VectorSourceError as err:
            logger.warning("camera views unavailable: %s", err)
            status = {"available": False, "notice": f"camera views unavailable: {err}"}
        self._status_notice = None if status["available"] else str(status["notice"])
        if self._status_notice is not None:
            self.notice.content = f"**No camera views:** {self._status_notice}"
        return self._status_notice is None

    def _set_visible(self, visible: bool) -> None:
        for node in self._nodes:
            node.visible = visible

    def _clear(self) -> None:
        for node in self._nodes:
            node.remove()
        self._nodes, self.frusta = [], []

    def show(self, element_id: str | None) -> None:
        """Draw the element's best views (none for None); a failed request leaves a notice, never raises."""
        with self._lock:
            self._clear()
            if not self._check_status():
                return
            if element_id is None:
                self.notice.content = HINT
                return
            try:
                found = fetch_views(self.api, element_id, int(self.count.value))
            except (VectorSourceError, KeyError, TypeError, ValueError) as err:
                logger.warning("camera views of element %s not shown: %s", element_id, err)
                self.notice.content = f"Camera views of element {element_id} not shown: {err}"
                return
            self._draw(element_id, found)

    def _draw(self, element_id: str, found: ElementViews) -> None:
        if not found.views:
            reason = found.notice or "no key-frame image sees it"
            self.notice.content = f"Element {element_id}: {reason}"
            return
        scene, visible = self.scene.server.scene, self.shown.value
        lifted = found.points_3d + self.offset + np.array([0.0, 0.0, ELEMENT_LIFT_M])
        if len(lifted) >= 2:
            segments = polyline_segments(lifted).astype(np.float32)
            self._nodes.append(
                scene.add_line_segments(
                    "/camera_views/element",
                    segments,
                    LIFTED_ELEMENT_RGB,
                    thickness=6.0,
                    thickness_units="screen",
                    visible=visible,
                )
            )
        for index, (view, camera, image) in enumerate(
            zip(found.views, found.cameras, found.images, strict=True)
        ):
            wxyz, position = frustum_pose(camera, self.offset)
            name = f"/camera_views/view_{index}"
            frustum = scene.add_camera_frustum(
                name,
                fov=camera.fov_y,
                aspect=camera.aspect,
                scale=FRUSTUM_DEPTH_M,
                thickness=2.0,
                thickness_units="screen",
                color=VIEW_FRUSTUM_RGB,
                image=image,
                wxyz=wxyz,
                position=position,
                visible=visible,
            )
            text = f"{view['channel']} @ {view['station_m']:.0f} m"
            label = scene.add_label(f"{name}/label", text, visible=visible)
            self.frusta.append(frustum)
            self._nodes += [label, frustum]  # the child first: removing the frustum removes its label
        lines = [f"**Element {element_id}:** {len(found.views)} views along it"]
        lines += [
            f"- {v['channel']} at {v['station_m']:.1f} m, {v['distance_m']:.1f} m away" for v in found.views
        ]
        self.notice.content = "\n".join(lines)


def attach_camera_views(scene: ReviewScene, source: object) -> CameraViews | None:
    """Camera views for a review that follows a backend; None (and a log line) for a file source."""
    if not isinstance(source, ApiVectorSource):
        logger.info("no camera views: the vectors come from a file, not from a backend (`--api`)")
        return None
    return CameraViews(scene, source)
