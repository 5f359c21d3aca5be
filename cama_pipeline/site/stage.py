"""The sites stage: drop night scenes, merge stationary clips, group overlapping scenes into sites, and
write `sites/index.json` plus one `sites/<site_id>/manifest.json` per site into the workspace."""

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, load_dataset
from cama_pipeline.site.aggregate import Aggregation, SceneTrack, aggregate
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.night import night_reason
from cama_pipeline.site.workspace import (
    KeyframesFile,
    WigoFile,
    default_workspace,
    fingerprint,
    keyframes_path,
    read_keyframes,
    read_wigo,
    site_manifest_path,
    sites_index_path,
    stored_fingerprint,
    wigo_path,
    write_site_manifest,
    write_sites_index,
)

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SitesResult:
    """What a run did: the aggregation, the files written, whether it was up to date."""

    workspace: Path
    aggregation: Aggregation
    manifests: dict[str, Path]
    skipped: bool
    seconds: float


def _manifest(
    site_scenes: list[tuple[WigoFile, KeyframesFile]], merged: dict[str, str], site_id: str
) -> dict[str, Any]:
    """One site's manifest: its scenes with frames and keyframes, and every image's fused pose."""
    scenes, poses = [], {}
    for wigo, kf in site_scenes:
        scenes.append(
            {
                "scene": wigo.scene,
                "scene_token": wigo.scene_token,
                "kind": "stationary" if kf.stationary else "moving",
                "merged_into": merged.get(wigo.scene),
                "frames": [f.to_json() for f in kf.frames],
            }
        )
        for p in wigo.poses:
            poses[p.token] = {
                "scene": wigo.scene,
                "channel": p.channel,
                "timestamp_us": p.timestamp_us,
                "translation": [float(v) for v in p.translation],
                "rotation": [float(v) for v in p.rotation],
            }
    return {"site_id": site_id, "scenes": scenes, "poses": poses}


def _read_scene_outputs(dataset: Dataset, workspace: Path) -> dict[str, tuple[WigoFile, KeyframesFile]]:
    """WIGO and keyframes outputs of every scene; FileNotFoundError names the stage to run first."""
    outputs = {}
    for scene in dataset.scenes:
        outputs[scene.name] = (
            read_wigo(wigo_path(workspace, scene.name)),
            read_keyframes(keyframes_path(workspace, scene.name)),
        )
    return outputs


def run(
    config: SiteConfig,
    dataset_root: Path,
    workspace: Path | None = None,
    *,
    overwrite: bool = False,
    dataset: Dataset | None = None,
) -> SitesResult:
    """Aggregate the data set's scenes into sites (default workspace: beside the data set)."""
    started = time.perf_counter()
    dataset = dataset if dataset is not None else load_dataset(Path(dataset_root), check_files=False)
    workspace = Path(workspace) if workspace is not None else default_workspace(Path(dataset_root))
    outputs = _read_scene_outputs(dataset, workspace)
    digest = fingerprint(
        "sites",
        code_version("cama_pipeline.site"),
        config.to_json(),
        [
            (s.name, s.description, outputs[s.name][0].fingerprint, outputs[s.name][1].fingerprint)
            for s in dataset.scenes
        ],
    )
    index_path = sites_index_path(workspace)
    tracks = []
    for scene in dataset.scenes:
        wigo, kf = outputs[scene.name]
        positions = np.array([p.translation for p in wigo.poses]).reshape(-1, 3)
        tracks.append(SceneTrack(scene.name, positions, kf.stationary, night_reason(scene, config)))
    result = aggregate(tracks, config)
    manifests = {site.site_id: site_manifest_path(workspace, site.site_id) for site in result.sites}
    if (
        not overwrite
        and stored_fingerprint(index_path) == digest
        and all(p.is_file() for p in manifests.values())
    ):
        logger.info("%s is up to date", index_path)
        return SitesResult(workspace, result, manifests, True, time.perf_counter() - started)
    for site in result.sites:
        chosen = [outputs[name] for name in site.scenes]
        write_site_manifest(manifests[site.site_id], _manifest(chosen, site.merged, site.site_id))
    index = {
        "fingerprint": digest,
        "config": config.to_json(),
        "sites": [{"site_id": s.site_id, "scenes": list(s.scenes), "merged": s.merged} for s in result.sites],
        "dropped": [{"scene": name, "reason": reason} for name, reason in result.dropped.items()],
    }
    write_sites_index(index_path, index)
    return SitesResult(workspace, result, manifests, False, time.perf_counter() - started)
