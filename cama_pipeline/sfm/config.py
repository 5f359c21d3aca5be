"""Parameters of odometry-guided SfM in one frozen, validated config, with the benchmark's named presets."""

import dataclasses
from dataclasses import dataclass
from typing import Literal

from cama_pipeline.sfm.gauge import GaugeSigmas

PresetName = Literal["plain", "rigid", "iterative"]
LossName = Literal["cauchy", "huber", "trivial"]


@dataclass(frozen=True)
class SfmConfig:
    """How views posed by odometry are triangulated and bundle-adjusted (paper: OGI, rigid prior, Alg. 1)."""

    rigid: bool = True
    """Hold the camera rig rigid in BA: one pose per keyframe, cameras fixed relative to CAM_FRONT.
    False = every image's pose free (plain BA)."""
    refine_extrinsics: bool = False
    """With `rigid`: jointly refine the camera-to-rig transforms (shared by all keyframes)."""
    iterative: bool = True
    """Iterative BA (Algorithm 1) instead of one BA after triangulation."""
    max_iterations: int = 5
    """Algorithm 1: iterations at most."""
    max_refinement_change: float = 0.0005
    """Algorithm 1: stop once changed observations / observations falls to this ratio or below."""
    max_reprojection_error_px: float = 4.0
    """Points with a larger reprojection error (in any image) are filtered."""
    min_track_length: int = 2
    """Points seen in fewer images are filtered."""
    min_triangulation_angle_deg: float = 1.0
    """Points whose rays meet at a smaller angle are filtered (depth not determined)."""
    max_image_reprojection_error_px: float = 2.0
    """Algorithm 1: keyframes (images in plain BA) whose mean reprojection error exceeds this are dropped."""
    odometry_priors: bool = True
    """Keep odometry in BA: relative-pose priors between consecutive keyframes and an absolute pose prior
    per keyframe (GNSS-like position, loose orientation anchor). Without them the first keyframe is held,
    and scale along the drive is only as good as the rig's baselines (measured on the tiny site: 3% drift
    in one clip, 21 cm relative error, against 1 cm with priors)."""
    relative_rotation_sigma_deg: float = 0.2
    """Odometry prior: sigma of the rotation between consecutive keyframes."""
    relative_translation_sigma_m: float = 0.05
    """Odometry prior: sigma of the translation between consecutive keyframes."""
    position_sigma_m: float = 1.0
    """Odometry prior: sigma of each keyframe's absolute position (GNSS-like)."""
    anchor_rotation_sigma_deg: float = 2.0
    """Odometry prior: sigma of each keyframe's absolute orientation (the anchor against free roll)."""
    anchor_gauge: bool = True
    """After BA, move the model onto all its odometry poses at once (weighted least squares, see
    `cama_pipeline.sfm.gauge`): WIGO's slow per-clip drift averages out instead of being inherited."""
    gauge_fit_scale: bool = True
    """Gauge fit: scale the model too (a similarity onto the odometry; see `cama_pipeline.sfm.gauge`). The
    images leave every clip 0.06-0.19 % too small (far points pull it small, near ones large;
    `bench/sfm_scale.py`), the same way in every clip, so no rigid placement averages it out. Whole sites,
    `bench/sfm.py` rows (e) rigid against (h) scaled: large 9.04 -> 6.76 cm, default 5.82 -> 5.91 cm (WIGO's own
    site-wide scale is 0.05 % off there); rotations unchanged."""
    gauge_position_sigma_m: float = 0.15
    """Gauge fit: sigma of an odometry position (WIGO's reported marginal, default site: 15-20 cm)."""
    gauge_tilt_sigma_deg: float = 0.035
    """Gauge fit: sigma of an odometry roll / pitch (gravity-aided; WIGO reports 0.035-0.04 deg)."""
    gauge_heading_sigma_deg: float = 0.25
    """Gauge fit: sigma of an odometry heading (WIGO reports 0.23-0.3 deg)."""
    max_camera_shift_m: float = 2.0
    """Keyframes (images) moved further than this from their initial pose by BA are flagged and dropped."""
    max_camera_rotation_deg: float = 5.0
    """Keyframes (images) rotated more than this from their initial pose by BA are flagged and dropped."""
    loss: LossName = "cauchy"
    """Robust loss on reprojection residuals."""
    loss_scale_px: float = 4.0
    """Scale of the robust loss. At 1 px the Cauchy loss shrank the models: default site, clip
    scene-0003, 0.68 % smaller than the truth (road points 1.3 cm too close below the cameras), against
    0.15 % at 4 px (0.08 % without a robust loss). Whole default site (clips + merge), 4 px against 1 px:
    5.82 cm / 0.0795 deg against 6.26 cm / 0.0795 deg (gauge-free 0.61 cm / 0.022 deg against
    0.57 cm / 0.022 deg, which a similarity measures without the scale), 0.48 px against 0.42 px,
    134 CPU s against 175 (BA converges in fewer steps)."""
    ba_max_iterations: int = 100
    """Solver iterations per BA at most."""
    ba_function_tolerance: float = 1e-6
    """BA stops once an iteration lowers the cost by less than this fraction (0 runs to COLMAP's gradient
    tolerance or the iteration limit). Tiny site, Algorithm 1 with priors and the gauge fit: 1e-6 halves
    the CPU time (solver steps 37/22/6 instead of 101/76/71) for the same errors to 0.01 cm / 0.0001 deg."""
    first_ba_max_iterations: int | None = 15
    """Algorithm 1: solver iterations at most of the first BA, the one on the raw triangulation whose
    outliers the next iterations filter and re-adjust (None: `ba_max_iterations`). Measured with a 1 px
    loss scale. Default site, largest
    clip (scene-0001 + stationary scene-0004, 474 images, 286k observations): 15 takes 70 CPU s against
    94 (solver steps 16/21/6 against 51/31/6), errors 6.27 cm / 0.0334 deg against 6.22 cm / 0.0334 deg
    (gauge-free 0.31 cm / 0.016 deg against 0.30 cm / 0.016 deg). Whole default site (clips + merge):
    175 CPU s against 235, errors 6.26 cm / 0.0795 deg against 6.25 cm / 0.0795 deg."""
    min_points: int = 20
    """Fewer triangulated points than this raises SfmError (clip cannot be reconstructed)."""
    min_registered_frames: int = 2
    """Fewer keyframes left after filtering than this raises SfmError."""
    num_threads: int = 1
    """Solver threads."""

    def __post_init__(self) -> None:
        positive = (
            "max_reprojection_error_px",
            "max_image_reprojection_error_px",
            "relative_rotation_sigma_deg",
            "relative_translation_sigma_m",
            "anchor_rotation_sigma_deg",
            "position_sigma_m",
            "gauge_position_sigma_m",
            "gauge_tilt_sigma_deg",
            "gauge_heading_sigma_deg",
            "max_camera_shift_m",
            "max_camera_rotation_deg",
            "loss_scale_px",
        )
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"SfmConfig.{name} must be > 0, got {getattr(self, name)}")
        at_least_one = ("max_iterations", "ba_max_iterations", "min_points", "num_threads")
        for name in at_least_one:
            if getattr(self, name) < 1:
                raise ValueError(f"SfmConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.first_ba_max_iterations is not None and self.first_ba_max_iterations < 1:
            raise ValueError(
                f"SfmConfig.first_ba_max_iterations must be >= 1 or None, got {self.first_ba_max_iterations}"
            )
        if self.min_track_length < 2:
            raise ValueError(f"SfmConfig.min_track_length must be >= 2, got {self.min_track_length}")
        if self.min_registered_frames < 1:
            raise ValueError(
                f"SfmConfig.min_registered_frames must be >= 1, got {self.min_registered_frames}"
            )
        if not 0 <= self.ba_function_tolerance < 1:
            raise ValueError(
                f"SfmConfig.ba_function_tolerance must be in [0, 1), got {self.ba_function_tolerance}"
            )
        if not 0 <= self.max_refinement_change < 1:
            raise ValueError(
                f"SfmConfig.max_refinement_change must be in [0, 1), got {self.max_refinement_change}"
            )
        if not 0 <= self.min_triangulation_angle_deg < 90:
            raise ValueError(
                f"SfmConfig.min_triangulation_angle_deg must be in [0, 90), got {self.min_triangulation_angle_deg}"
            )
        if self.loss not in ("cauchy", "huber", "trivial"):
            raise ValueError(f"SfmConfig.loss must be cauchy, huber or trivial, got {self.loss!r}")
        if self.refine_extrinsics and not self.rigid:
            raise ValueError("SfmConfig.refine_extrinsics needs rigid=True (plain BA has no rig)")

    def gauge_sigmas(self) -> GaugeSigmas:
        """The weights of the gauge fit (see `cama_pipeline.sfm.gauge`)."""
        return GaugeSigmas(
            self.gauge_position_sigma_m, self.gauge_tilt_sigma_deg, self.gauge_heading_sigma_deg
        )

    @classmethod
    def preset(cls, name: str, **overrides: object) -> "SfmConfig":
        """The benchmark's variants: `plain` (guided triangulation + plain BA), `rigid` (+ rigid BA),
        `iterative` (+ iterative BA, the default); odometry priors as the default unless overridden."""
        variants: dict[str, dict[str, bool]] = {
            "plain": {"rigid": False, "iterative": False},
            "rigid": {"rigid": True, "iterative": False},
            "iterative": {"rigid": True, "iterative": True},
        }
        if name not in variants:
            raise ValueError(f"unknown SfM preset {name!r}; choose one of {', '.join(variants)}")
        return dataclasses.replace(cls(), **{**variants[name], **overrides})  # type: ignore[arg-type]
