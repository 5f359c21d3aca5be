"""Semantic label ids shared by image masks, BEV rasters and every stage that reads them.

Ids 0-4 are the BEV raster classes of DESIGN.md; image masks add the classes a 2D segmentation
network would also give (vehicle, static object, sky, ego body).
"""

from enum import IntEnum


class Semantic(IntEnum):
    """Per-pixel class in image masks and BEV rasters."""

    BACKGROUND = 0  # terrain, sidewalk, anything not listed below
    ROAD = 1
    CURB = 2  # curb / road edge
    LANE_MARKING = 3
    CROSSWALK = 4
    VEHICLE = 5  # moving and parked vehicles
    STATIC_OBJECT = 6  # buildings, poles
    SKY = 7
    EGO = 8  # the ego vehicle's own body (trunk in CAM_BACK)
    UNOBSERVED = 255  # BEV rasters only: no camera saw this cell


BEV_CLASSES: tuple[Semantic, ...] = (
    Semantic.BACKGROUND,
    Semantic.ROAD,
    Semantic.CURB,
    Semantic.LANE_MARKING,
    Semantic.CROSSWALK,
)

ROAD_SURFACE_IDS: tuple[int, ...] = (int(Semantic.ROAD), int(Semantic.LANE_MARKING), int(Semantic.CROSSWALK))
"""Ids of the road surface vehicles drive on: the road and the paint on it."""

DYNAMIC_CLASSES: tuple[Semantic, ...] = (Semantic.VEHICLE, Semantic.EGO)
"""Classes that features, matching and surface fitting must ignore."""

INSTANCE_ID_BASE = 1000
"""Instance masks store `semantic_id * 1000 + instance_index` (0 = none), as the CAMA release does."""
