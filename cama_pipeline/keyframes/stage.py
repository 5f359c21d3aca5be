"""The keyframes stage: resynchronise each scene's images into frames and choose keyframes from the fused
WIGO poses; writes `keyframes/<scene>.json` into the workspace."""

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from cama_pipeline.code_version import code_version
from cama_pipeline.keyframes.config import KeyframeConfig
from cama_pipeline.keyframes.resync import ImageStamp, resync
from cama_pipeline.keyframes.selection import is_stationary, path_length_m, select_keyframes
from cama_pipeline.site.workspace import (
    FrameRecord,
    KeyframesFile,
    WigoFile,
    default_workspace,
    fingerprint,
    keyframes_path,
    read_wigo,
    stored_fingerprint,
    wigo_path,
    write_keyframes,
)

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class KeyframesResult:
    """What a run did: the files per scene and which were up to date."""

    workspace: Path
    files: dict[str, Path]
    skipped: tuple[str, ...]
    seconds: float


def scene_names(workspace: Path, scenes: Sequence[str] | None) -> list[str]:
    """The requested scenes, or every scene WIGO wrote; FileNotFoundError when WIGO has not run."""
    if scenes:
        missing = [s for s in scenes if not wigo_path(workspace, s).is_file()]
        if missing:
            raise FileNotFoundError(f"{workspace / 'wigo'}: no poses for {missing}; run `cama wigo` first")
        return list(scenes)
    names = sorted(p.stem for p in (Path(workspace) / "wigo").glob("*.json"))
    if not names:
        raise FileNotFoundError(f"{workspace / 'wigo'}: no WIGO poses; run `cama wigo` first")
    return names


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
    workspace: Path | None = None,
    *,
    scenes: Sequence[str] | None = None,
    overwrite: bool = False,
) -> KeyframesResult:
    """Resync and select keyframes for the scenes WIGO fused (default workspace: beside the data set)."""
    started = time.perf_counter()
    workspace = Path(workspace) if workspace is not None else default_workspace(Path(dataset_root))
    files: dict[str, Path] = {}
    skipped: list[str] = []
    for name in scene_names(workspace, scenes):
        source = wigo_path(workspace, name)
        path = keyframes_path(workspace, name)
        files[name] = path
        digest = fingerprint(
            "keyframes", code_version("cama_pipeline.keyframes"), config.to_json(), stored_fingerprint(source)
        )
        if not overwrite and stored_fingerprint(path) == digest:
            skipped.append(name)
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
    return KeyframesResult(workspace, files, tuple(skipped), time.perf_counter() - started)
