"""The keyframes stage: resynchronise each scene's images into frames and choose keyframes from the fused
WIGO poses; writes `keyframes/<scene>.json` into the workspace."""

import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from cama_pipeline.code_version import code_version
from cama_pipeline.fingerprints import fingerprint, is_up_to_date, stored_fingerprint
from cama_pipeline.keyframes.config import KeyframeConfig
from cama_pipeline.keyframes.io import FrameRecord, KeyframesFile, read_keyframes, write_keyframes
from cama_pipeline.keyframes.resync import ImageStamp, resync
from cama_pipeline.keyframes.selection import is_stationary, path_length_m, select_keyframes
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.wigo.io import WigoFile, read_wigo
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


def scene_names(workspace: Workspace, scenes: Sequence[str] | None) -> list[str]:
    """The requested scenes, or every scene WIGO wrote; FileNotFoundError when WIGO has not run."""
    folder = workspace.stage_dir("wigo")
    if scenes:
        missing = [s for s in scenes if not workspace.wigo(s).is_file()]
        if missing:
            raise FileNotFoundError(f"{folder}: no poses for {missing}; run `cama wigo` first")
        return list(scenes)
    names = workspace.wigo_scenes()
    if not names:
        raise FileNotFoundError(f"{folder}: no WIGO poses; run `cama wigo` first")
    return names


def summary(kf: KeyframesFile) -> dict[str, Any]:
    """A scene's figures for the stage result: frames and keyframes, whether stationary, path and times."""
    return {
        "frames": len(kf.frames),
        "keyframes": len(kf.keyframes),
        "stationary": kf.stationary,
        "path_length_m": kf.path_length_m,
        "max_time_diff_us": kf.max_time_diff_us,
        "max_time_range_us": kf.max_time_range_us,
    }


def keyframes_of(wigo: WigoFile, config: KeyframeConfig, digest: str) -> KeyframesFile:
    """Frames and keyframes of one scene from its fused poses."""
    stamps = [ImageStamp(p.token, p.channel, p.timestamp_us) for p in wigo.poses]
    frames = resync(stamps, config.reference_channel, int(round(config.max_time_diff_ms * 1000)))
    by_token = {p.token: p for p in wigo.poses}
    refs = [by_token[f.reference_token] for f in frames]
    translation = np.array([p.translation for p in refs]).reshape(-1, 3)
    rotation = Rotation.from_quat(np.array([p.rotation for p in refs]).reshape(-1, 4), scalar_first=True)
    stationary = is_stationary(translation, config)
    reasons = select_keyframes(
        rotation.as_matrix().reshape(-1, 3, 3), translation, config, stationary=stationary
    )
    records = tuple(
        FrameRecord(
            index=i,
            timestamp_us=f.timestamp_us,
            images={c: im.token for c, im in f.images.items()},
            time_diff_us=f.time_diff_us,
            keyframe=bool(reason),
            reason=reason,
        )
        for i, (f, reason) in enumerate(zip(frames, reasons, strict=True))
    )
    return KeyframesFile(
        scene=wigo.scene,
        fingerprint=digest,
        config=config.to_json(),
        stationary=stationary,
        path_length_m=path_length_m(translation),
        max_time_diff_us=max((f.time_diff_us for f in frames), default=0),
        max_time_range_us=max((f.time_range_us for f in frames), default=0),
        frames=records,
    )


def run(
    config: KeyframeConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    scenes: Sequence[str] | None = None,
    overwrite: bool = False,
) -> StageResult:
    """Resync and select keyframes for the scenes WIGO fused (default workspace: beside the data set); one item
    per scene, its report the scene's `summary`."""
    started = time.perf_counter()
    ws = Workspace.resolve(workspace, Path(dataset_root))
    items: list[ItemResult] = []
    for name in scene_names(ws, scenes):
        source = ws.wigo(name)
        path = ws.keyframes(name)
        digest = fingerprint(
            "keyframes", code_version("cama_pipeline.keyframes"), config.to_json(), stored_fingerprint(source)
        )
        if not overwrite and is_up_to_date(path, digest):
            items.append(ItemResult(name, path, summary(read_keyframes(path)), skipped=True))
            continue
        result = keyframes_of(read_wigo(source), config, digest)
        write_keyframes(path, result)
        logger.info(
            "scene %s: %d frames, %d keyframes%s, max time diff %.1f ms",
            name,
            len(result.frames),
            len(result.keyframes),
            " (stationary: all kept)" if result.stationary else "",
            result.max_time_diff_us / 1000,
        )
        items.append(ItemResult(name, path, summary(result), skipped=False))
    return StageResult("keyframes", ws, tuple(items), time.perf_counter() - started)
