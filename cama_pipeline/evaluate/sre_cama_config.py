"""Settings of the `cama` SRE protocol: the rules of CAMA's published metric code, as constants one can vary.

The `strict` protocol (cama_pipeline/evaluate/sre.py) is the project's own: every camera with lanes counts, the
distance is taken from every skeleton pixel to the projected curve. The `cama` protocol reproduces how the
CAMA release scores a map (its `metric.py`, `dataset.py`, `reproject.py` and `main.py`, read for this), so our
figures compare with the paper's:

- images and instance masks are resampled to 960x540 (nearest neighbour through the scaled pinhole matrix);
- the map is densified to 1 cm, moved into the ego (chassis) frame of the frame's front camera and cropped
  there to a box; each camera projects the kept points (in front of it, inside the image) and the projected
  element becomes the set of integer pixels it hits, in (row, column) order; fewer than 10 pixels: dropped;
- an image instance is its skeleton (10 pixels at least); a smoothing spline is fitted to the skeleton and 60
  normals, +-20 px long, are taken at spline parameters 0.2 to 0.8; a normal that crosses the projected
  polyline exactly once gives one distance, the others are ignored; a pair's cost is the mean distance;
- Hungarian matching over all (image, projected) pairs, unmatched pairs cost 500 and a pair is kept below 300
  (so any pair with one crossing normal can match); only lane markings are scored;
- a camera without a matched pair does not count at all (nor its precision and recall), frame 0 of each
  scene is skipped; means per camera -> per frame -> per scene, F1 from the mean precision and recall.
"""

from dataclasses import dataclass
from typing import Literal

SreProtocol = Literal["strict", "cama"]
"""`strict`: the project's own SRE; `cama`: the rules of CAMA's published metric code."""

SRE_PROTOCOLS: tuple[SreProtocol, ...] = ("strict", "cama")


@dataclass(frozen=True)
class CamaProtocolConfig:
    """Constants of the `cama` protocol; the defaults are the values in CAMA's published code."""

    image_width_px: int = 960
    """Width the instance masks are resampled to and the map is projected at."""
    image_height_px: int = 540
    """Height the instance masks are resampled to and the map is projected at."""
    crop_x_m: tuple[float, float] = (-50.0, 50.0)
    """Kept map points: ego (chassis) x range, metres (x forward)."""
    crop_y_m: tuple[float, float] = (-100.0, 100.0)
    """Kept map points: ego y range, metres (y left)."""
    crop_z_m: tuple[float, float] = (-200.0, 200.0)
    """Kept map points: ego z range, metres."""
    densify_m: float = 0.01
    """Spacing the map polylines are densified to before cropping and projecting (CAMA: 0.1 px of a
    0.1 m raster)."""
    min_points: int = 10
    """Fewest skeleton pixels of an image instance and fewest distinct pixels of a projected element."""
    spline_smoothing: float = 10.0
    """Smoothing factor of the skeleton spline per skeleton pixel (scipy splprep `s` = this x count)."""
    spline_range: tuple[float, float] = (0.2, 0.8)
    """Range of the spline parameter (0 to 1 over the skeleton) where the normals are taken."""
    normals: int = 60
    """Number of normals along the spline."""
    search_px: float = 20.0
    """Half length of each normal, pixels: a crossing farther than this is not seen."""
    no_crossing_cost: float = 500.0
    """Matching cost of a pair where no normal crosses the projection."""
    match_below: float = 300.0
    """A Hungarian pair is kept when its cost is below this."""
    skip_first_frame: bool = True
    """Leave out frame 0 of each scene (CAMA iterates from index 1)."""
    frame_pose_channel: str | None = "CAM_FRONT"
    """Every camera of a frame is projected through the ego pose of this channel's image, as CAMA derives the
    chassis pose from the front camera's odometry; None: each image through its own ego pose."""
    pixel_polyline: bool = True
    """The projected polyline is CAMA's: the distinct integer pixels (floored) in (row, column) order; False:
    the projected points in their order along the element (a diagnostic, not CAMA's rule)."""

    def __post_init__(self) -> None:
        if self.image_width_px <= 0 or self.image_height_px <= 0:
            raise ValueError("CamaProtocolConfig: image_width_px and image_height_px must be > 0")
        for name in ("crop_x_m", "crop_y_m", "crop_z_m"):
            low, high = getattr(self, name)
            if not low < high:
                raise ValueError(f"CamaProtocolConfig.{name}: low must be below high, got ({low}, {high})")
        if not self.densify_m > 0 or not self.search_px > 0 or not self.spline_smoothing >= 0:
            raise ValueError(
                "CamaProtocolConfig: densify_m and search_px > 0, spline_smoothing >= 0 required"
            )
        if self.min_points < 4 or self.normals < 1:
            raise ValueError("CamaProtocolConfig: min_points >= 4 (a cubic spline) and normals >= 1 required")
        low, high = self.spline_range
        if not 0.0 <= low <= high <= 1.0:
            raise ValueError(f"CamaProtocolConfig.spline_range must lie in [0, 1], got {self.spline_range}")
        if not 0 < self.match_below < self.no_crossing_cost:
            raise ValueError("CamaProtocolConfig: 0 < match_below < no_crossing_cost required")
