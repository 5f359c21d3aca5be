"""Site aggregation as pure functions over scene tracks: moving day scenes whose trajectories come within
`overlap_radius_m` of each other share a site (transitively); each stationary clip joins the site of its
nearest moving clip; night scenes and stationary clips with no moving clip near are dropped with a reason."""

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


@dataclass(frozen=True)
class Site:
    """One site: its scenes (moving first, in input order) and the stationary merges."""

    site_id: str
    scenes: tuple[str, ...]
    merged: dict[str, str] = field(default_factory=dict)
    """stationary scene -> the moving scene it was merged into."""


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
    """Connected components of the "trajectories within radius" graph (union-find)."""
    parent = list(range(len(moving)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(len(moving)):
        for j in range(i + 1, len(moving)):
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
        if not moving:
            dropped[still.name] = "stationary and no moving day clip to merge with"
            continue
        distances = [track_distance_m(still.positions, m.positions) for m in moving]
        best = int(np.argmin(distances))
        if distances[best] > config.stationary_merge_max_m:
            dropped[still.name] = (
                f"stationary and the nearest moving clip ({moving[best].name}) is {distances[best]:.0f} m away "
                f"(> {config.stationary_merge_max_m:g} m)"
            )
            continue
        merged_into[still.name] = moving[best].name
        logger.info(
            "scene %s: stationary, merged into %s (%.1f m)", still.name, moving[best].name, distances[best]
        )
    sites = []
    for number, group in enumerate(sorted(groups, key=min), start=1):
        names = [moving[i].name for i in group]
        merged = {s: m for s, m in merged_into.items() if m in names}
        sites.append(Site(f"site-{number:03d}", tuple(names + list(merged)), merged))
    for name, reason in dropped.items():
        logger.info("scene %s dropped: %s", name, reason)
    return Aggregation(tuple(sites), dropped)
