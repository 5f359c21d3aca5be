"""Every parameter of pair selection in one frozen, validated config."""

from dataclasses import dataclass


@dataclass(frozen=True)
class PairsConfig:
    """Parameters of sequential pairs and of the HSP rules (paper: "Homography-guided Spatial Pairs")."""

    sequential_window: int = 3
    """A keyframe image is paired with the same camera's images up to this many keyframes later."""
    rig_window: int = 1
    """Overlapping rig cameras are paired within the same keyframe and up to this many keyframes apart."""
    rig_max_axis_angle_deg: float = 80.0
    """Two rig cameras overlap when their optical axes are at most this far apart (from the extrinsics)."""
    knn: int = 0
    """Nearest camera centres considered per image (scipy cKDTree); 0 considers every camera within the
    radius (a fixed k misses co-visible cameras where many clips, or a stationary clip, crowd one place)."""
    knn_radius_m: float = 40.0
    """Neighbours farther than this are never spatial pairs. Footprints reach `footprint_max_range_m` ahead, so
    cameras 30-40 m apart can still share half their ground: on the default site 30 m missed 2.5 % of the
    strongly co-visible pairs, 40 m misses 0.1 % (50 m adds nothing)."""
    max_dz_m: float = 3.0
    """Largest height difference of two camera centres (the paper's Δz): other levels, other roads."""
    level_free_heights: bool = True
    """Before the height rule, move the clips whose heights WIGO left free (2D logged poses, no GNSS: their
    offsets are the gauge's, metres apart, not the road's) to the road the other clips drove
    (`cama_pipeline.site.heights`); else the rule drops every pair between clips more than `max_dz_m` apart."""
    face_to_face_angle_deg: float = 150.0
    """Optical axes at least this far apart, each camera in front of the other: facing each other."""
    face_to_face_max_distance_m: float = 12.0
    """Facing cameras closer than this are dropped (huge viewpoint change over little shared ground)."""
    footprint_max_range_m: float = 25.0
    """Ground footprints reach at most this far from the camera (far road is too oblique to match)."""
    footprint_grid: tuple[int, int] = (20, 72)
    """Ground samples around the camera (ranges, azimuths) projected into the image to trace the footprint."""
    repeat_distance_m: float = 0.25
    """An image whose camera centre is this close to an earlier image of the same camera and scene (and whose axis
    is within `repeat_angle_deg`) repeats that view: paired with it, temporally and in the rig, but not spatially
    (`cama_pipeline.pairs.repeats`). Keyframes of a moving clip lie 1 m or more apart; 0 turns repeats off."""
    repeat_angle_deg: float = 2.0
    """Largest angle between the optical axes of an image and the one it repeats."""
    min_footprint_overlap: float = 0.4
    """Least overlap of two ground footprints (shared area over the larger one) to keep a spatial pair. It tracks
    the true mutual co-visibility closely (correlation 0.98 on the default site), so this sets the pair count:
    with a 40 m radius, 0.3 keeps 12.4 % of all pairs, 0.35 10.5 %, 0.4 9.1 % (97.4 % recall of strongly
    co-visible pairs), 0.45 8.0 % (94.8 %)."""

    def __post_init__(self) -> None:
        for name in ("sequential_window", "rig_window", "knn"):
            if getattr(self, name) < 0:
                raise ValueError(f"PairsConfig.{name} must be positive, got {getattr(self, name)}")
        if self.repeat_distance_m < 0 or not 0 < self.repeat_angle_deg <= 180:
            raise ValueError(
                "PairsConfig: repeat_distance_m must be >= 0 and repeat_angle_deg in (0, 180], got "
                f"{self.repeat_distance_m} and {self.repeat_angle_deg}"
            )
        for name in ("knn_radius_m", "max_dz_m", "face_to_face_max_distance_m", "footprint_max_range_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"PairsConfig.{name} must be > 0, got {getattr(self, name)}")
        for name in ("rig_max_axis_angle_deg", "face_to_face_angle_deg"):
            if not 0 < getattr(self, name) <= 180:
                raise ValueError(f"PairsConfig.{name} must be in (0, 180], got {getattr(self, name)}")
        if not 0 <= self.min_footprint_overlap <= 1:
            raise ValueError(
                f"PairsConfig.min_footprint_overlap must be in [0, 1], got {self.min_footprint_overlap}"
            )
        if min(self.footprint_grid) < 2:
            raise ValueError(
                f"PairsConfig.footprint_grid needs at least 2 x 2 samples, got {self.footprint_grid}"
            )
