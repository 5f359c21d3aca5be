"""The whole reconstruction path as one call: wigo -> keyframes -> sites -> pairs -> segment -> features -> sfm ->
surface -> VMA proposals, for any nuScenes-layout data set. Only composes the stages' own `run`s (each skips what
is up to date), times them, and names the stage that failed.

Image masks come from the run's `masks` choice (`cama_pipeline.data.masks`): the segment stage runs only when that
choice needs predicted masks (`prediction_needed`: a data set without masks and no imported ones, or `predicted`),
else it is recorded as skipped with the reason; features, SfM and the surface read the masks the choice resolves to.

Outputs are the stages' own files in the workspace (`cama_pipeline.workspace`); the proposals of site `s` are
`proposals/<s>.json` (an annotation set in the frame of that site's reconstructed rasters, `surface/<s>/bev/`).
"""

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from cama_pipeline.code_version import CodeChangedError
from cama_pipeline.data.errors import DatasetError
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.workspace import Workspace
from cama_studio.config import PipelineConfig

logger = logging.getLogger(__name__)

STAGES = ("wigo", "keyframes", "sites", "pairs", "segment", "features", "sfm", "surface", "propose")


@dataclass(frozen=True)
class Skipped:
    """What a stage call returns when the run does not need the stage, and why."""

    reason: str


class PipelineError(RuntimeError):
    """A stage failed; the message names the stage and its error, and says whether the input was at fault."""

    def __init__(self, stage: str, err: Exception, *, bad_input: bool) -> None:
        self.stage = stage
        self.bad_input = bad_input
        """The data set or a file the caller named (a checkpoint) is missing or unreadable; False: the stage's
        own work failed (e.g. every SfM clip failed, no road points to fit)."""
        what = "stopped on bad input" if bad_input else "failed"
        super().__init__(f"stage {stage} {what}: {err}")


def _is_bad_input(stage: str, err: Exception) -> bool:
    """Whether a stage's error is the caller's input (the data set, a named file or checkpoint), not its work.

    The workspace is the path's own output, so an error about it (WorkspaceError) is a stage failure here; code
    changed on disk under the running process (CodeChangedError) is the caller's to fix by restarting."""
    if isinstance(err, DatasetError | FileNotFoundError | CodeChangedError):
        return True
    if stage == "propose":
        from models.vma.checkpoint import CheckpointError  # imported by the propose stage already

        return isinstance(err, CheckpointError)
    return False


@dataclass
class PipelineResult:
    """Seconds per stage and where the outputs are."""

    workspace: Path
    seconds: dict[str, float] = field(default_factory=dict)
    proposals: dict[str, Path] = field(default_factory=dict)
    checkpoint: Path | None = None
    """The VMA checkpoint version folder the learned proposer used (None: rule-based, or not reached)."""
    skipped: dict[str, str] = field(default_factory=dict)
    """Stages the run did not need, with the reason (e.g. segment: the data set has its own masks)."""


def _stage_calls(
    dataset_root: Path, workspace: Path, config: PipelineConfig, overwrite: bool
) -> dict[str, Callable[[], object]]:
    """One zero-argument call per reconstruction stage, each with its table of `config`; imported lazily so
    `cama run --help` stays fast."""
    from cama_pipeline.features.stage import run as run_features
    from cama_pipeline.keyframes import run as run_keyframes
    from cama_pipeline.pairs.stage import run as run_pairs
    from cama_pipeline.sfm.stage import run as run_sfm
    from cama_pipeline.site.stage import run as run_sites
    from cama_pipeline.surface import run as run_surface
    from cama_pipeline.wigo import run as run_wigo

    root, ws, c = dataset_root, workspace, config
    scenes = c.scenes or None
    return {
        "segment": lambda: _segment(root, ws, c, overwrite),
        "wigo": lambda: run_wigo(c.wigo, root, ws, scenes=scenes, overwrite=overwrite),
        "keyframes": lambda: run_keyframes(c.keyframes, root, ws, scenes=scenes, overwrite=overwrite),
        "sites": lambda: run_sites(c.sites, root, ws, scenes=scenes, overwrite=overwrite),
        "pairs": lambda: run_pairs(c.pairs, root, ws, overwrite=overwrite),
        "features": lambda: run_features(c.features, root, ws, masks=c.masks, overwrite=overwrite),
        "sfm": lambda: run_sfm(
            c.sfm,
            root,
            ws,
            executor=c.executor,
            workers=c.workers,
            merge_config=c.sfm_merge,
            masks=c.masks,
            overwrite=overwrite,
        ),
        "surface": lambda: run_surface(
            c.surface, root, ws, poses=c.surface_poses, masks=c.masks, overwrite=overwrite
        ),
    }


def _segment(dataset_root: Path, workspace: Path, config: PipelineConfig, overwrite: bool) -> Skipped | None:
    """The segment stage when the run's mask choice needs predicted masks, else why not (`prediction_needed`)."""
    from cama_pipeline.data.masks import prediction_needed

    reason = prediction_needed(config.masks, dataset_root, workspace)
    if reason is not None:
        logger.info("segment skipped: %s", reason)
        return Skipped(reason)
    from cama_pipeline.segment.stage import run as run_segment

    run_segment(
        config.segment,
        dataset_root,
        workspace,
        executor=config.executor,
        workers=config.workers,
        scenes=config.scenes or None,
        overwrite=overwrite,
    )
    return None


def _propose_sites(workspace: Path, config: PipelineConfig, overwrite: bool, result: PipelineResult) -> None:
    """VMA proposals for every site from its reconstructed rasters, recorded in `result`."""
    from models.vma.propose import propose

    ws = Workspace(workspace)
    for site_id in read_site_ids(ws.sites_index()):
        proposed = propose(
            ws.surface_bev(site_id),
            ws.proposals(site_id),
            proposer=config.proposer,
            checkpoint=config.checkpoint if config.proposer != "rule" else None,
            min_confidence=config.propose.min_confidence,
            inference=config.propose.inference,
            rule=config.propose.rule_for(Workspace(workspace).surface_bev(site_id)),
            overwrite=overwrite,
        )
        result.proposals[site_id] = proposed.out
        result.checkpoint = proposed.checkpoint


def run(
    dataset_root: Path,
    workspace: Path | None = None,
    config: PipelineConfig | None = None,
    *,
    stop_after: str = "propose",
    overwrite: bool = False,
    on_stage: Callable[[str], None] | None = None,
) -> PipelineResult:
    """Run every stage up to `stop_after` in order; PipelineError naming the stage when one fails."""
    if stop_after not in STAGES:
        raise ValueError(f"stop_after must be one of {', '.join(STAGES)}, got {stop_after!r}")
    config = config or PipelineConfig()
    dataset_root = Path(dataset_root)
    workspace = Workspace.resolve(workspace, dataset_root).root
    result = PipelineResult(workspace)
    calls = _stage_calls(dataset_root, workspace, config, overwrite)
    for stage in STAGES[: STAGES.index(stop_after) + 1]:
        if on_stage is not None:
            on_stage(stage)
        started = time.perf_counter()
        try:
            if stage == "propose":
                _propose_sites(workspace, config, overwrite, result)
            elif isinstance(outcome := calls[stage](), Skipped):
                result.skipped[stage] = outcome.reason
        except (ValueError, FileNotFoundError, RuntimeError) as err:
            raise PipelineError(stage, err, bad_input=_is_bad_input(stage, err)) from err
        result.seconds[stage] = time.perf_counter() - started
        logger.info("stage %s done in %.1f s", stage, result.seconds[stage])
    return result
