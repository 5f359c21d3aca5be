"""Every parameter of road surface reconstruction in one frozen, validated config."""

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

from cama_pipeline.surface.coverage import CoverageConfig
from cama_pipeline.surface.steps import KerbStepConfig

PoseSource = Literal["ground_truth", "wigo", "sfm"]
POSE_SOURCES: tuple[str, ...] = ("ground_truth", "wigo", "sfm")


def require(config: object, names: Iterable[str], valid: Callable[[Any], bool], requirement: str) -> None:
    """A ValueError naming the first field of `names` whose value is not `valid` ("Config.field must be
    <requirement>, got <value>")."""
    for name in names:
        value = getattr(config, name)
        if not valid(value):
            raise ValueError(f"{type(config).__name__}.{name} must be {requirement}, got {value}")


@dataclass(frozen=True)
class RefineConfig:
    """Parameters of the multi-view refinement of the road elevation (`surface.refine` in a run
    configuration; see `cama_pipeline.surface.refine`)."""

    enabled: bool = True
    sweeps: tuple[tuple[float, float], ...] = ((0.06, 0.02), (0.015, 0.0075))
    """(half range, step) in metres of the height hypotheses of each sweep, around the surface the sweep
    before left: coarse first, then fine."""
    downsample: int = 1
    """Images averaged over blocks of this many pixels a side before they are compared (1: as they are)."""
    vertex_stride: int = 3
    """Every n-th vertex along rows and columns takes part (the residual lives on the 1 m control grid)."""
    edge_margin_m: float = 1.0
    """Road vertices this close to a vertex that is not road (a kerb, the road region's edge) are left out."""
    semantic_weight: float = 1.0
    """Weight of the class frequencies' variance across views beside the colour variance."""
    smoothness_weight: float = 30.0
    """Weight of the residual's squared second differences against the sweeps' confidence-weighted
    heights (a unit of confidence is a 100 % drop of a control point's cost at its best height). 1 until the
    mask-free twins showed that a stiffer residual (a smooth correction that no single control point's noisy
    best height bends) lifts lane marking and curb (`bench/surface_variants.py`, README "How stiff the
    refinement is")."""
    ridge_weight: float = 0.03
    """Weight of the residual's square: where no paint or edge constrains a control point, it stays at 0."""

    def __post_init__(self) -> None:
        if not self.sweeps or any(not (0 < step <= half) for half, step in self.sweeps):
            raise ValueError(
                f"RefineConfig.sweeps must be (half range, step) pairs with 0 < step <= half, got {self.sweeps}"
            )
        for name in ("downsample", "vertex_stride"):
            if getattr(self, name) < 1:
                raise ValueError(f"RefineConfig.{name} must be >= 1, got {getattr(self, name)}")
        for name in ("edge_margin_m", "semantic_weight", "smoothness_weight"):
            if getattr(self, name) < 0:
                raise ValueError(f"RefineConfig.{name} must be >= 0, got {getattr(self, name)}")
        if not self.ridge_weight > 0:
            raise ValueError(f"RefineConfig.ridge_weight must be > 0, got {self.ridge_weight}")


@dataclass(frozen=True)
class JointConfig:
    """Parameters of the joint optimisation of the mesh by differentiable rendering (`surface.joint` in a run
    configuration; see `cama_pipeline.surface.joint`)."""

    epochs: int = 0
    """Passes over all keyframe images; 0 (the default) leaves the observation vote as it is: on the default site
    two passes moved no IoU by more than 0.009 and cost 0.2-0.3 dB PSNR (`bench/surface_joint.py`)."""
    images_per_batch: int = 8
    rays_per_image: int = 4096
    """Ground pixels rendered per image and step."""
    colour_lr: float = 0.002
    semantic_lr: float = 0.01
    height_lr: float = 0.001
    """Adam step (metres) on the lift of the smooth surface on its control grid."""
    vertex_height_lr: float = 0.0005
    """Adam step (metres) on the per-vertex height residual."""
    semantic_weight: float = 0.1
    smoothness_weight: float = 10.0
    """Weight of the mean squared height difference (m^2) of neighbouring vertices."""
    edge_weight: float = 0.02
    """Share of the smoothness kept between a road-class vertex and an off-road one (a kerb's edge)."""
    ridge_weight: float = 1.0
    """Weight of the mean squared residual (m^2)."""
    search_m: tuple[float, float] = (0.1, 0.3)
    """(below, above) the smooth surface: the heights a ray's first hit is searched over."""
    samples: int = 48
    """Points along each ray in that search."""
    vote_after: bool = False
    """After the passes, vote every cell's colour and class again on the optimised surface (kerbs included) in
    place of the optimised attributes (the vote on the true surface is what `bench/surface_split.py` measures as
    the ceiling of any geometry)."""

    def __post_init__(self) -> None:
        require(self, ("epochs",), lambda value: value >= 0, ">= 0")
        require(self, ("images_per_batch", "rays_per_image"), lambda value: value >= 1, ">= 1")
        require(self, ("samples",), lambda value: value >= 2, ">= 2")
        rates = ("colour_lr", "semantic_lr", "height_lr", "vertex_height_lr")
        weights = ("semantic_weight", "smoothness_weight", "edge_weight", "ridge_weight")
        require(self, (*rates, *weights), lambda value: value >= 0, ">= 0")
        if len(self.search_m) != 2 or min(self.search_m) < 0 or sum(self.search_m) <= 0:
            raise ValueError(f"JointConfig.search_m must be (below, above) >= 0, got {self.search_m}")


@dataclass(frozen=True)
class SurfaceConfig:
    """Parameters of the RoMe-style surface: points initialisation, elevation MLP, mesh optimisation."""

    resolution_m: float = 0.1
    """Grid spacing of the mesh vertices and of the BEV rasters (one vertex per raster cell)."""
    region_radius_m: float = 12.0
    """The mesh covers the cells within this distance of a surface point (its road region): farther, the
    elevation is extrapolated (bench/surface.py: RMSE grows with the radius when only the strip is there)."""
    use_trajectory_strip: bool = True
    """Add the road strip under the keyframe poses (covers the road where SfM points are sparse)."""
    strip_x_range_m: tuple[float, float] = (-1.0, 3.5)
    """Ego x range (rear, front) of the road strip under each keyframe (origin: ground under the rear axle)."""
    strip_half_width_m: float = 2.0
    """Half width (ego y) of the road strip: the ego's ground plane (its roll and pitch follow the road)
    over about its lane, which pins the lateral slope that a strip under the body alone leaves open."""
    strip_spacing_m: float = 0.25
    """Sample spacing of the strip points."""
    use_sfm_points: bool = True
    """Add the SfM points labelled road/marking/crosswalk when the workspace has them."""
    sfm_max_error_px: float = 2.0
    """SfM points with a larger mean reprojection error are left out."""
    sfm_gate_m: float = 1.0
    """SfM points farther than this from the surface fitted to the strip (then from each refit) are left out (see
    `fit`); nearer ones are weighed by the Huber loss. 0.1 m until the hilly twin showed it keeps out the points
    past a grade change (`bench/surface_gate.py`)."""
    pe_frequencies: int = 4
    """Positional-encoding octaves of the elevation MLP; few octaves keep the surface smooth."""
    mlp_width: int = 64
    """Hidden units per layer of the elevation MLP (two hidden layers)."""
    elevation_iterations: int = 800
    """Adam steps fitting the elevation MLP to the surface points."""
    refit_iterations: int = 400
    """Adam steps of the second fit, the strip and the gated SfM points, from the first (see `fit`)."""
    sfm_gate_rounds: int = 4
    """Fits with gated SfM points: each round gates the points again against the surface the last one fitted
    and fits again while the inliers grow (see `fit`). One: the points are gated against the strip's surface
    alone, which beyond the strip continues like a plane, so on a road whose grade changes the points past
    `sfm_gate_m` of that plane never join."""
    elevation_lr: float = 5e-3
    huber_m: float = 0.05
    """Robust (Huber) loss scale of the elevation fit: residuals beyond it count linearly."""
    smoothness_weight: float = 30.0
    """Weight (m^3) of the curvature prior: the mean thin-plate energy (m^-2) of the elevation over the
    road region, added to the Huber point loss (m). Roads bend slowly, so away from the points the
    surface extrapolates like a plane instead of wandering (0: no prior)."""
    smoothness_step_m: float = 1.0
    """Central-difference step of the curvature prior."""
    control_spacing_m: float = 1.0
    """The MLP is evaluated on a control grid this coarse and interpolated to the vertices (it is smooth)."""
    max_range_m: float = 21.0
    """Vertices farther than this from a camera are not projected into it (too oblique, too blurred).
    Default site, SfM poses, 25 -> 21 m: proposal mAP (observed truth) 0.891 -> 0.932 and the simulated
    annotator 1.81x -> 1.85x (the raster's far edges are less distorted), curb IoU 0.39 -> 0.35, the
    other IoUs within 0.004, elevation unchanged; 18 m: mAP 0.937, annotator 1.83x, curb IoU 0.31."""
    min_depth_m: float = 0.5
    depth_tolerance: float = 0.03
    """Relative depth slack of the visibility (z-buffer) test, plus `resolution_m` absolute."""
    curb_height_m: float = 0.13
    """Height above the road at which every cell is voted again: cells off the road at road level, or whose
    views agree more at this height, take curb or background from it (a curb's face and top smear beyond
    it at road level, see `labels`); 0 turns this off."""
    epochs: int = 0
    """Passes over all keyframe images optimising colour, semantics and (optionally) the elevation MLP.
    0 by default: on the default site one epoch moved the elevation away from the points (RMSE 3.1 ->
    4.5 cm, ground-truth poses) and changed neither colour nor classes (their lr are 0), for 70 s."""
    images_per_batch: int = 16
    vertices_per_image: int = 12000
    """Visible vertices sampled per image and optimisation step (all of them in the first, averaging pass)."""
    colour_lr: float = 0.0
    """Adam step on the per-vertex colours in the optimisation epochs; 0 keeps the weighted means of the
    observation pass (measured on the default site: Adam's per-vertex steps on sparse batches add noise,
    -1.7 dB PSNR, see bench/surface.py)."""
    semantic_lr: float = 0.0
    """Adam step on the per-vertex semantic logits; 0 keeps the observation pass's class votes."""
    refine_elevation: bool = True
    """Refine the elevation MLP through the photometric/semantic loss during mesh optimisation."""
    refine_lr: float = 5e-4
    anchor_weight: float = 1.0
    """Weight of the surface-point loss kept while refining elevation (holds the MLP near the points)."""
    semantic_weight: float = 0.1
    torch_threads: int = 1
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """`auto`: the GPU when torch sees one, else the CPU with `torch_threads` threads."""
    seed: int = 0
    coverage: CoverageConfig = field(default_factory=CoverageConfig)
    """What the report calls weakly observed (`surface.coverage`)."""
    refine: RefineConfig = field(default_factory=RefineConfig)
    """The photometric refinement of the road elevation before the observation pass (`surface.refine`)."""
    joint: JointConfig = field(default_factory=JointConfig)
    """The joint optimisation of colour, semantics and heights by differentiable rendering (`surface.joint`)."""
    kerb_step: KerbStepConfig = field(default_factory=KerbStepConfig)
    """Which off-road cells stand `curb_height_m` above the road (`surface.kerb_step`; needs
    `curb_height_m` > 0)."""

    def __post_init__(self) -> None:
        positive = (
            "resolution_m",
            "region_radius_m",
            "strip_half_width_m",
            "strip_spacing_m",
            "sfm_max_error_px",
            "sfm_gate_m",
            "elevation_lr",
            "huber_m",
            "smoothness_step_m",
            "control_spacing_m",
            "max_range_m",
            "min_depth_m",
            "refine_lr",
        )
        require(self, positive, lambda value: value > 0, "> 0")
        at_least_one = (
            "pe_frequencies",
            "mlp_width",
            "images_per_batch",
            "vertices_per_image",
            "torch_threads",
            "sfm_gate_rounds",
        )
        require(self, at_least_one, lambda value: value >= 1, ">= 1")
        counts = ("elevation_iterations", "refit_iterations", "epochs")
        weights = ("depth_tolerance", "smoothness_weight", "anchor_weight", "semantic_weight")
        require(self, (*counts, *weights, "colour_lr", "semantic_lr"), lambda value: value >= 0, ">= 0")
        if not self.strip_x_range_m[0] < self.strip_x_range_m[1]:
            raise ValueError(
                f"SurfaceConfig.strip_x_range_m must be (rear, front), got {self.strip_x_range_m}"
            )
        if self.control_spacing_m < self.resolution_m:
            raise ValueError("SurfaceConfig.control_spacing_m must be at least resolution_m")
        if self.device not in ("auto", "cpu", "cuda"):
            raise ValueError(f"SurfaceConfig.device must be auto, cpu or cuda, got {self.device!r}")
