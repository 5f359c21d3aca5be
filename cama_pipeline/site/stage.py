"""The sites stage: drop night scenes, merge stationary clips, group overlapping scenes of one location into
sites, and write `sites/index.json` plus one `sites/<site_id>/manifest.json` per site into the workspace."""

import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, load_dataset
from cama_pipeline.fingerprints import fingerprint, is_up_to_date
from cama_pipeline.keyframes.io import KeyframesFile, read_keyframes
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.site.aggregate import Aggregation, SceneTrack, Site, aggregate
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.io import write_site_manifest, write_sites_index
from cama_pipeline.site.night import night_reason
from cama_pipeline.wigo.io import WigoFile, read_wigo
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


def _manifest(site_scenes: list[tuple[WigoFile, KeyframesFile]], site: Site) -> dict[str, Any]:
    """One site's manifest: its scenes with frames and keyframes, and every image's fused pose."""
    scenes, poses = [], {}
    for wigo, kf in site_scenes:
        scenes.append(
            {
                "scene": wigo.scene,
                "scene_token": wigo.scene_token,
                "kind": "stationary" if kf.stationary else "moving",
                "merged_into": site.merged.get(wigo.scene),
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
    return {"site_id": site.site_id, "location": site.location, "scenes": scenes, "poses": poses}


def _read_scene_outputs(dataset: Dataset, workspace: Workspace) -> dict[str, tuple[WigoFile, KeyframesFile]]:
    """WIGO and keyframes outputs of every scene; FileNotFoundError names the stage to run first."""
    outputs = {}
    for scene in dataset.scenes:
        outputs[scene.name] = (
            read_wigo(workspace.wigo(scene.name)),
            read_keyframes(workspace.keyframes(scene.name)),
        )
    return outputs


def _index(aggregation: Aggregation, digest: str, config: SiteConfig) -> dict[str, Any]:
    """The content of `sites/index.json` (schema in `cama_pipeline.site.io`)."""
    return {
        "fingerprint": digest,
        "config": config.to_json(),
        "sites": [
            {"site_id": s.site_id, "location": s.location, "scenes": list(s.scenes), "merged": s.merged}
            for s in aggregation.sites
        ],
        "dropped": [{"scene": name, "reason": reason} for name, reason in aggregation.dropped.items()],
    }


def run(
    config: SiteConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    scenes: Sequence[str] | None = None,
    overwrite: bool = False,
    dataset: Dataset | None = None,
) -> StageResult:
    """Aggregate the data set's scenes (those named in `scenes`, else all) into sites (default workspace: beside
    the data set). One item per site (its manifest; report: its `sites/index.json` entry), the run's report the
    whole index (with the dropped scenes); an up-to-date index skips every site."""
    started = time.perf_counter()
    if dataset is None:
        dataset = load_dataset(Path(dataset_root), check_files=False, scenes=scenes or None)
    ws = Workspace.resolve(workspace, Path(dataset_root))
    outputs = _read_scene_outputs(dataset, ws)
    digest = fingerprint(
        "sites",
        code_version("cama_pipeline.site"),
        config.to_json(),
        [
            (
                s.name,
                s.description,
                s.location,
                outputs[s.name][0].fingerprint,
                outputs[s.name][1].fingerprint,
            )
            for s in dataset.scenes
        ],
    )
    index_path = ws.sites_index()
    tracks = []
    for scene in dataset.scenes:
        wigo, kf = outputs[scene.name]
        positions = np.array([p.translation for p in wigo.poses]).reshape(-1, 3)
        tracks.append(
            SceneTrack(scene.name, positions, kf.stationary, night_reason(scene, config), scene.location)
        )
    result = aggregate(tracks, config)
    index = _index(result, digest, config)
    manifests = {site.site_id: ws.site_manifest(site.site_id) for site in result.sites}
    skipped = (
        not overwrite and is_up_to_date(index_path, digest) and all(p.is_file() for p in manifests.values())
    )
    if skipped:
        logger.info("%s is up to date", index_path)
    else:
        for site in result.sites:
            chosen = [outputs[name] for name in site.scenes]
            write_site_manifest(manifests[site.site_id], _manifest(chosen, site))
        write_sites_index(index_path, index)
    items = tuple(
        ItemResult(entry["site_id"], manifests[entry["site_id"]], entry, skipped) for entry in index["sites"]
    )
    return StageResult("sites", ws, items, time.perf_counter() - started, report=index)
