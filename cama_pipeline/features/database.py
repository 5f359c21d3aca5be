"""The site's COLMAP database: cameras from the calibration, images by data-set-relative name, features,
and the verified pairs read back. The only module that writes features into it."""

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pycolmap

from cama_pipeline.cameras import CameraView
from cama_pipeline.features.interface import Features


@contextmanager
def open_database(path: Path) -> Iterator[pycolmap.Database]:
    """The database at `path` (created when missing), closed afterwards."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    database = pycolmap.Database.open(str(path))
    try:
        yield database
    finally:
        database.close()


def _camera_key(view: CameraView) -> tuple[float, ...]:
    k = view.intrinsic
    return (k[0, 0], k[1, 1], k[0, 2], k[1, 2], float(view.width), float(view.height))


class FeatureStore:
    """Adds images with their features to an open database, one PINHOLE camera per distinct calibration."""

    def __init__(self, database: pycolmap.Database) -> None:
        self._db = database
        self._cameras: dict[tuple[float, ...], int] = {}
        for camera in database.read_all_cameras():
            fx, fy, cx, cy = camera.params
            self._cameras[(fx, fy, cx, cy, float(camera.width), float(camera.height))] = camera.camera_id
        self.image_ids = {image.name: image.image_id for image in database.read_all_images()}

    def has(self, name: str) -> bool:
        """Whether the image is in the database with its keypoints (a rerun skips it)."""
        image_id = self.image_ids.get(name)
        return image_id is not None and self._db.exists_keypoints(image_id)

    def keypoint_count(self, name: str) -> int:
        """Keypoints of an image already in the database."""
        return int(self._db.num_keypoints_for_image(self.image_ids[name]))

    def _camera_id(self, view: CameraView) -> int:
        key = _camera_key(view)
        if key not in self._cameras:
            camera = pycolmap.Camera(
                model="PINHOLE", width=view.width, height=view.height, params=list(key[:4])
            )
            self._cameras[key] = self._db.write_camera(camera)
        return self._cameras[key]

    def add(self, view: CameraView, features: Features) -> int:
        """Write the image (if new), its keypoints and descriptors; returns its image id."""
        image_id = self.image_ids.get(view.name)
        if image_id is None:
            image = pycolmap.Image(name=view.name, camera_id=self._camera_id(view))
            image_id = self._db.write_image(image)
            self.image_ids[view.name] = image_id
        self._db.write_keypoints(image_id, features.keypoints)
        self._db.write_descriptors(
            image_id, pycolmap.FeatureDescriptors(pycolmap.FeatureExtractorType.SIFT, features.descriptors)
        )
        return image_id


def prune_unlisted(database: pycolmap.Database, listed: set[frozenset[str]]) -> int:
    """Delete the matches and two-view geometries of pairs not in `listed` (left by an earlier pair list, which
    later stages would otherwise still use); returns how many pairs went."""
    names = {image.image_id: image.name for image in database.read_all_images()}
    matched = set(database.read_num_matches()[0]) | set(database.read_two_view_geometry_num_inliers()[0])
    pruned = 0
    for pair_id in matched:
        first, second = pycolmap.pair_id_to_image_pair(pair_id)
        if frozenset((names[first], names[second])) not in listed:
            database.delete_matches(first, second)
            database.delete_two_view_geometry(first, second)
            pruned += 1
    return pruned


def verified_pairs(database: pycolmap.Database) -> dict[tuple[str, str], int]:
    """Inlier counts of the geometrically verified pairs, by (nameA, nameB) in database id order."""
    names = {image.image_id: image.name for image in database.read_all_images()}
    pair_ids, geometries = database.read_two_view_geometries()
    verified = {}
    for pair_id, geometry in zip(pair_ids, geometries, strict=True):
        first, second = pycolmap.pair_id_to_image_pair(pair_id)
        if len(geometry.inlier_matches) > 0:
            verified[(names[first], names[second])] = len(geometry.inlier_matches)
    return verified
