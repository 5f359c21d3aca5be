"""Site aggregation as pure functions over scene tracks: moving day scenes of one location whose trajectories
come within `overlap_radius_m` of each other share a site (transitively); each stationary clip joins the site of
its nearest moving clip of its location; night scenes and stationary clips with no moving clip near are dropped
with a reason.

Scenes of different locations (nuScenes' `log.location`) never share a site: each location has its own map
frame, and the coordinates of two cities overlap."""

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from cama_pipeline.site.config import SiteConfig

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SceneTrack:
    """What aggregation needs of a scene: its fused positions and its kind."""

    name: str
    positions: np.ndarray
    """(N, 3) fused global positions (e.g. of its frames)."""
    stationary: bool
    night_reason: str | None = None
    """Why it is a night scene, None for day."""
    location: str = ""
    """The scene's `log.location`; only scenes of the same location are compared."""


@dataclass(frozen=True)
class Site:
    """One site: its scenes (moving first, in input order) and the stationary merges."""

    site_id: str
    scenes: tuple[str, ...]
    merged: dict[str, str] = field(default_factory=dict)
    """stationary scene -> the moving scene it was merged into."""
    location: str = ""
    """The location every scene of the site shares."""


@dataclass(frozen=True)
class Aggregation:
    """The sites and the dropped scenes with their reasons."""

    sites: tuple[Site, ...]
    dropped: dict[str, str]


def track_distance_m(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest horizontal distance between any position of `a` and any of `b`."""
    if len(a) == 0 or len(b) == 0:
        return float("inf")
    distance, _ = cKDTree(np.asarray(b)[:, :2]).query(np.asarray(a)[:, :2], k=1)
    return float(np.min(distance))


def _overlap_groups(moving: list[SceneTrack], radius_m: float) -> list[list[int]]:
    """Connected components of the "same location and trajectories within radius" graph (union-find)."""
    parent = list(range(len(moving)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(len(moving)):
        for j in range(i + 1, len(moving)):
            if moving[i].location != moving[j].location:
                continue
            if track_distance_m(moving[i].positions, moving[j].positions) <= radius_m:
                parent[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i in range(len(moving)):
        groups.setdefault(root(i), []).append(i)
    return list(groups.values())


def aggregate(tracks: list[SceneTrack], config: SiteConfig) -> Aggregation:
    """Group scenes into sites (see the module docstring); reasons are logged and returned."""
    dropped: dict[str, str] = {}
    for track in tracks:
        if track.night_reason is not None:
            dropped[track.name] = track.night_reason
        elif len(track.positions) == 0:
            dropped[track.name] = "no fused poses"
    day = [t for t in tracks if t.name not in dropped]
    moving = [t for t in day if not t.stationary]
    groups = _overlap_groups(moving, config.overlap_radius_m)
    merged_into: dict[str, str] = {}
    for still in (t for t in day if t.stationary):
        target = _merge_target(still, moving, config, dropped)
        if target is not None:
            merged_into[still.name] = target
    sites = []
    for number, group in enumerate(sorted(groups, key=min), start=1):
        names = [moving[i].name for i in group]
        merged = {s: m for s, m in merged_into.items() if m in names}
        location = moving[group[0]].location
        sites.append(Site(f"site-{number:03d}", tuple(names + list(merged)), merged, location))
    for name, reason in dropped.items():
        logger.info("scene %s dropped: %s", name, reason)
    return Aggregation(tuple(sites), dropped)


def _merge_target(
    still: SceneTrack, moving: list[SceneTrack], config: SiteConfig, dropped: dict[str, str]
) -> str | None:
    """The moving clip of its location a stationary clip joins, or None with the reason put into `dropped`."""
    candidates = [m for m in moving if m.location == still.location]
    if not candidates:
        where = f" at its location ({still.location})" if still.location else ""
        dropped[still.name] = f"stationary and no moving day clip{where} to merge with"
        return None
    distances = [track_distance_m(still.positions, m.positions) for m in candidates]
    best = int(np.argmin(distances))
    if distances[best] > config.stationary_merge_max_m:
        dropped[still.name] = (
            f"stationary and the nearest moving clip ({candidates[best].name}) is {distances[best]:.0f} m away "
            f"(> {config.stationary_merge_max_m:g} m)"
        )
        return None
    logger.info(
        "scene %s: stationary, merged into %s (%.1f m)", still.name, candidates[best].name, distances[best]
    )
    return candidates[best].name
