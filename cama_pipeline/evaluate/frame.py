"""The frame a reconstruction's rasters are in, against the generator's world: the 2D similarity that carries the
true ego positions onto the positions the surface stage placed the site with.

A reconstruction sits in the world where its poses' gauge puts it (WIGO's, which SfM inherits): off by decimetres
and, on a small site, by a fraction of a percent of scale (tiny site 9011: SfM poses 22 cm from the truth on
average, 1.4 cm after the best similarity). Inside, rasters and images agree with each other to a centimetre or
two. An annotator sees only those, so the truth an annotator can draw, and a model proposing on the rasters can
find, is the generator's truth carried by this similarity; the placement error itself is the poses' (measured
by `cama_pipeline.sfm.baseline.pose_errors`), not the annotators' or the proposer's. The rasters are 2D, so the
similarity is too: scale, rotation about the vertical and translation, fitted to the keyframes' ego positions
(`skimage.transform.SimilarityTransform`, a least-squares fit).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from skimage.transform import SimilarityTransform

from cama_pipeline.data import load_dataset
from cama_pipeline.site.io import manifest_scenes, read_site_manifest
from cama_pipeline.surface.outputs import read_report
from cama_pipeline.surface.poses import posed_views
from cama_pipeline.workspace import Workspace


class FrameError(ValueError):
    """A reconstruction whose frame cannot be found (no surface report, too few posed keyframes)."""


@dataclass(frozen=True)
class ReconstructionFrame:
    """reconstruction_from_world in the ground plane: x' = scale * R(rotation) x + translation (global metres)."""

    scale: float
    rotation_rad: float
    translation: tuple[float, float]
    poses: str
    """The pose source the surface stage used (`ground_truth`, `wigo` or `sfm`)."""
    keyframes: int
    """Keyframes both the truth and that source have a pose for: the positions fitted."""
    shift_m: float
    """Mean distance the similarity moves the true keyframe positions: how far the rasters are from the world."""
    residual_m: float
    """Mean distance left between the moved true positions and the source's: the error inside the frame."""

    def apply(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) global x, y of the world carried into the reconstruction (extra columns, such as z, dropped)."""
        return np.asarray(self._transform()(np.asarray(xy, dtype=np.float64)[:, :2]))

    def world_of(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) the world's x, y of points in the reconstruction (the inverse of `apply`)."""
        return np.asarray(self._transform().inverse(np.asarray(xy, dtype=np.float64)[:, :2]))

    def _transform(self) -> SimilarityTransform:
        return SimilarityTransform(scale=self.scale, rotation=self.rotation_rad, translation=self.translation)

    def as_dict(self) -> dict[str, object]:
        """The frame's figures, as benches record them (scale as parts per thousand off 1, rotation in degrees)."""
        return {
            "poses": self.poses,
            "keyframes": self.keyframes,
            "shift_cm": self.shift_m * 100,
            "residual_cm": self.residual_m * 100,
            "scale_error_permille": (self.scale - 1.0) * 1000,
            "rotation_deg": float(np.degrees(self.rotation_rad)),
            "translation_m": list(self.translation),
        }


def fitted_frame(world_xy: np.ndarray, reconstruction_xy: np.ndarray, poses: str) -> ReconstructionFrame:
    """The least-squares 2D similarity from (N, 2) true positions onto the reconstruction's (N >= 3)."""
    if len(world_xy) < 3:
        raise FrameError(
            f"{len(world_xy)} keyframes posed by both the truth and {poses}: at least 3 are needed"
        )
    transform = SimilarityTransform.from_estimate(world_xy, reconstruction_xy)
    if not transform:
        raise FrameError(f"no similarity fits the {len(world_xy)} keyframe positions ({poses} poses)")
    moved = np.asarray(transform(world_xy))
    return ReconstructionFrame(
        scale=float(transform.scale),
        rotation_rad=float(transform.rotation),
        translation=(float(transform.translation[0]), float(transform.translation[1])),
        poses=poses,
        keyframes=len(world_xy),
        shift_m=float(np.linalg.norm(moved - world_xy, axis=1).mean()),
        residual_m=float(np.linalg.norm(moved - reconstruction_xy, axis=1).mean()),
    )


def reconstruction_frame(dataset_root: Path, workspace: Workspace, site_id: str) -> ReconstructionFrame:
    """The frame of site `site_id`'s surface in `workspace` (made from the synthetic data set `dataset_root`, whose
    ground truth holds the true poses); FrameError naming the site when its surface report is missing."""
    report_path = workspace.surface_report(site_id)
    if not report_path.is_file():
        raise FrameError(f"site {site_id}: no surface report at {report_path} (run `cama surface` first)")
    poses = str(read_report(report_path)["poses"])
    manifest = read_site_manifest(workspace.site_manifest(site_id))
    dataset = load_dataset(Path(dataset_root), scenes=manifest_scenes(manifest))
    true = {
        v.token: v.world_from_ego[:2, 3]
        for v in posed_views(dataset, manifest, workspace, site_id, "ground_truth")
    }
    used = {
        v.token: v.world_from_ego[:2, 3] for v in posed_views(dataset, manifest, workspace, site_id, poses)
    }
    tokens = sorted(set(true) & set(used))
    try:
        return fitted_frame(
            np.array([true[t] for t in tokens]).reshape(-1, 2),
            np.array([used[t] for t in tokens]).reshape(-1, 2),
            poses,
        )
    except FrameError as error:
        raise FrameError(f"site {site_id}: {error}") from None
