"""The VMA loop's job kinds: `retrain` (fine-tune on the corrections of every site in the database, or of the job's
site alone, behind the evaluation gates: validation mAP, and the simulated annotator's correction time on the
validation sites, `app.review_effort.review_time`) and
`refresh_proposals` (re-run the proposer and replace proposals nobody has touched).

Retraining runs in a child process (spawned, so no lock or thread state of the server is inherited) because
`models.vma.retrain.retrain_from_corrections` is one long call: the job polls the child, reports its progress,
and terminates it when the job is cancelled or the server stops, or when it hangs (its processes use no CPU for
`Settings.retrain_stall_s`; the job then fails saying so, instead of staying "running" until a lead cancels it).
The child turns the trainer's step log records (`step i/n loss x`, written by `models.vma.train.fit` at its first
step, every 50 steps and its last) into
`retrain_progress.json` ({"step", "total", "loss"}) in the job folder; the job's progress field follows them
(0.1 to 0.9 over the steps; the evaluations of the current model before and of the candidate after take the
rest), and its message names the step and the loss. The child writes `retrain.json` in the
job folder: {"candidate", "promoted", "labels", "negatives", "current_metrics", "candidate_metrics"} or
{"error"}. Checkpoint versions are written atomically by `models.vma.checkpoint`, so a killed child leaves at
most an unpromoted staging folder. `models.vma` (torch) is imported inside the functions that need it, so that
the server starts without it (see `app/backend/vma_loop.py`).
"""

import json
import logging
import multiprocessing
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, Field

from annotations.schema import AnnotationSet
from app.backend.config import Settings
from app.backend.crud.refresh import refresh_proposals
from app.backend.jobs.kinds import every_site_annotations, site_annotations
from app.backend.jobs.process_cpu import tree_cpu_seconds
from app.backend.jobs.runner import JobCancelled, JobContext, JobKind, JobResult
from app.backend.schemas import STRICT
from app.backend.vma_loop import preaccept_threshold
from cama_pipeline.io import atomic_write_json
from models.vma.gate import TIME_CONFIDENCE, review_saving_confidence

if TYPE_CHECKING:
    from models.vma.retrain import Corrections, RetrainConfig
    from models.vma.validation import ValidationEntry

logger = logging.getLogger(__name__)

RETRAIN_FILE = "retrain.json"
PROGRESS_FILE = "retrain_progress.json"
TRAIN_LOGGER = "models.vma.train"
"""The logger whose `step %d/%d loss %.4f ...` records report the training steps (of either network)."""
FIT_SPAN = (0.1, 0.9)
"""Job progress at the first and the last training step."""
PROPOSALS_FILE = "proposals.json"
POLL_S = 0.5
TERMINATE_GRACE_S = 5.0
"""How long a cancelled retraining child has to end on SIGTERM before it is killed: a child can hold SIGTERM
blocked (CPython's multiprocessing resource tracker blocks it while it starts its server, and a child was seen
deadlocked there, every thread waiting on a lock), and a join without a limit then never returns."""
STALL_CPU_S = 1.0
"""CPU seconds a retraining child (with the processes below it) must use within `Settings.retrain_stall_s` to
count as working; one that uses less is hung (`app.backend.jobs.process_cpu`) and is stopped."""
LOOP_USER = "vma-loop"
"""Edit-log username of loop changes when the proposer names no author."""


class RetrainParams(BaseModel):
    """Parameters of a `retrain` job (the model config comes from the registry's promoted checkpoint)."""

    model_config = STRICT
    steps: int = Field(default=300, ge=1, le=100_000, description="Fine-tuning batches.")
    batch_size: int = Field(default=8, ge=1, le=256)
    learning_rate: float = Field(default=2e-4, gt=0.0, le=1.0)
    tolerance: float = Field(
        default=0.0, ge=0.0, le=1.0, description="Gate: promote when mAP >= current - this."
    )
    refresh_after_promotion: bool = Field(default=True, description="Queue a proposal refresh when promoted.")
    every_site: bool = Field(
        default=True,
        description="Learn from the corrections of every site in the database (false: the job's site only).",
    )
    annotator_gate: bool = Field(
        default=True,
        description="Second gate: the simulated annotator's correction time on the validation sites.",
    )
    time_tolerance: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="Annotator gate: promote when the correction time <= current * (1 + this).",
    )
    time_confidence: float = Field(
        default=TIME_CONFIDENCE,
        ge=0.0,
        lt=1.0,
        description="Annotator gate: promote only when the time saved holds in at least this share of bootstrap "
        "resamples of the validation sites (0: the totals alone decide).",
    )
    replay_share: float = Field(
        default=0.0,
        ge=0.0,
        lt=1.0,
        description="Element-mask network: the share of fine-tuning crops cut from a few of its own training "
        "sites (rehearsal, so it does not forget them; 0: none). It slows the adoption of a team's own "
        "drawing conventions where they differ from the model's.",
    )


class RefreshParams(BaseModel):
    """Parameters of a `refresh_proposals` job."""

    model_config = STRICT
    proposer: Literal["auto", "learned", "rule"] = Field(
        default="auto", description="auto: the learned model when a registry is configured, else rule-based."
    )
    min_confidence: float = Field(default=0.1, ge=0.0, le=1.0, description="Drop proposals below this.")


def training_view(annotations: AnnotationSet) -> AnnotationSet:
    """The set as retraining should see it: elements the loop pre-accepted that no person has touched since
    (still `accepted` by LOOP_USER; any human change sets the author) are the model's own output, not labels."""
    elements = [
        e.with_changes(review_state="proposed")
        if e.review_state == "accepted" and e.author == LOOP_USER
        else e
        for e in annotations.elements
    ]
    return annotations.model_copy(update={"elements": elements})


class StepReporter(logging.Handler):
    """Writes the trainer's step records (`step i/n loss x`) to a JSON file the parent process polls."""

    def __init__(self, path: Path) -> None:
        super().__init__(level=logging.INFO)
        self.path = path

    def emit(self, record: logging.LogRecord) -> None:
        """Record step, total and loss of a step record; other records are ignored."""
        args = record.args if isinstance(record.args, tuple) else ()
        if not str(record.msg).startswith("step ") or len(args) < 3:
            return
        try:
            step = {"step": int(args[0]), "total": int(args[1]), "loss": float(args[2])}  # type: ignore[call-overload, arg-type]
        except (TypeError, ValueError):
            return
        atomic_write_json(self.path, step)


def read_step(path: Path) -> dict[str, Any] | None:
    """The last step the child reported, or None (none yet, or unreadable)."""
    try:
        step: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        return step if {"step", "total", "loss"} <= step.keys() else None
    except (OSError, ValueError):
        return None


def step_progress(step: dict[str, Any] | None, elapsed_s: float) -> tuple[float, str]:
    """The job's progress and message for the child's last reported step."""
    if step is None:
        return FIT_SPAN[0], f"fine-tuning: preparing and evaluating the current model ({elapsed_s:.0f} s)"
    done, total = int(step["step"]), max(int(step["total"]), 1)
    progress = FIT_SPAN[0] + (FIT_SPAN[1] - FIT_SPAN[0]) * min(done / total, 1.0)
    message = f"fine-tuning: step {done}/{total}, loss {float(step['loss']):.4f} ({elapsed_s:.0f} s)"
    if done >= total:
        message += "; evaluating the candidate"
    return progress, message


def _retrain_child(
    registry: Path,
    corrections: list["Corrections"],
    validation: list["ValidationEntry"],
    config: "RetrainConfig",
    annotator_gate: bool,
    replay_share: float,
    out: Path,
) -> None:
    """Child process body: retrain the registry's network (the MapTR-style model or the element-mask network,
    whichever its promoted version is) and write the outcome (or the error) to `out`, the steps beside it."""
    from app.review_effort.review_time import review_time
    from models.vma.checkpoint import checkpoint_kind
    from models.vma.element_masks.checkpoint import KIND as MASK_KIND
    from models.vma.element_masks.config import MaskTrainConfig
    from models.vma.element_masks.retrain import MaskRetrainConfig, retrain_masks_from_corrections
    from models.vma.retrain import retrain_from_corrections

    logging.basicConfig(level=logging.INFO)
    logging.getLogger(TRAIN_LOGGER).addHandler(StepReporter(out.parent / PROGRESS_FILE))
    review = review_time if annotator_gate else None
    try:
        if checkpoint_kind(registry) == MASK_KIND:
            train = MaskTrainConfig(
                steps=config.train.steps,
                batch_size=config.train.batch_size,
                learning_rate=config.train.learning_rate,
                damaged_copies=2,
            )
            mask_config = MaskRetrainConfig(
                train,
                config.tolerance,
                config.time_tolerance,
                config.min_labels,
                replay_share=replay_share,
                time_confidence=config.time_confidence,
            )
            result = retrain_masks_from_corrections(
                registry, corrections, validation, mask_config, review=review
            )
        else:
            result = retrain_from_corrections(registry, corrections, validation, config, review=review)
        payload: dict[str, Any] = {
            "candidate": result.candidate.name,
            "promoted": result.promoted,
            "labels": result.labels,
            "negatives": result.negatives,
            "current_metrics": result.current_metrics,
            "candidate_metrics": result.candidate_metrics,
        }
    except Exception as error:  # noqa: BLE001 - handed to the parent as the job's failure message
        payload = {"error": f"{type(error).__name__}: {error}"}
    atomic_write_json(out, payload, indent=2)


class StallWatch:
    """Tells when a child process (with the processes below it) has used under `STALL_CPU_S` of CPU for `limit_s`
    seconds: hung, not slow (see `app.backend.jobs.process_cpu`). `limit_s` 0, or a system without `/proc`: never."""

    def __init__(self, pid: int, limit_s: float) -> None:
        self.pid, self.limit_s = pid, limit_s
        self.mark_cpu_s, self.mark_at = tree_cpu_seconds(pid), time.monotonic()
        self.checked_at = self.mark_at

    def stalled(self) -> bool:
        """Whether the CPU time has stood still (within `STALL_CPU_S`) for `limit_s`; /proc is read at most four
        times per `limit_s` (and every 5 s at most), not on every poll."""
        now = time.monotonic()
        if self.limit_s <= 0 or self.mark_cpu_s is None or now - self.checked_at < min(5.0, self.limit_s / 4):
            return False
        self.checked_at = now
        cpu_s = tree_cpu_seconds(self.pid)
        if cpu_s is None:
            return False
        if cpu_s - self.mark_cpu_s >= STALL_CPU_S:
            self.mark_cpu_s, self.mark_at = cpu_s, now
            return False
        return now - self.mark_at >= self.limit_s


def _end_child(process: "multiprocessing.process.BaseProcess") -> None:
    """SIGTERM, then SIGKILL after `TERMINATE_GRACE_S` if the child is still there."""
    process.terminate()
    process.join(TERMINATE_GRACE_S)
    if process.is_alive():
        logger.warning(
            "retraining process %s ignored SIGTERM for %.0f s; killing it", process.pid, TERMINATE_GRACE_S
        )
        process.kill()
        process.join()


def _run_child(
    context: JobContext,
    args: tuple[Any, ...],
    out: Path,
    target: Callable[..., None] = _retrain_child,
    *,
    stall_s: float = 0.0,
) -> dict[str, Any]:
    """Run `target` (`_retrain_child`) in a spawned process, reporting its steps while it runs; on cancel, end it
    (`_end_child`); when it has hung for `stall_s` (`StallWatch`; 0: never), end it and fail, saying so."""
    progress_file = out.parent / PROGRESS_FILE
    progress_file.unlink(missing_ok=True)
    process = multiprocessing.get_context("spawn").Process(target=target, args=(*args, out), daemon=True)
    process.start()
    started = time.monotonic()
    watch = StallWatch(process.pid or 0, stall_s)
    try:
        while process.is_alive():
            process.join(POLL_S)
            step = read_step(progress_file)
            context.report(*step_progress(step, time.monotonic() - started))
            if process.is_alive() and watch.stalled():
                _end_child(process)
                where = (
                    "before its first step" if step is None else f"after step {step['step']}/{step['total']}"
                )
                raise RuntimeError(
                    f"the retraining process {process.pid} hung {where}: it used under {STALL_CPU_S:.0f} s of CPU "
                    f"in {stall_s:.0f} s and was stopped (CAMA_RETRAIN_STALL_S); nothing was promoted, start the "
                    "retrain again"
                )
    except JobCancelled:
        _end_child(process)
        raise
    if not out.is_file():
        raise RuntimeError(f"the retraining process ended without a result (exit code {process.exitcode})")
    payload: dict[str, Any] = json.loads(out.read_text(encoding="utf-8"))
    if "error" in payload:
        raise RuntimeError(f"retraining failed: {payload['error']}")
    return payload


def _count(annotations: AnnotationSet, states: tuple[str, ...]) -> int:
    return sum(e.review_state in states for e in annotations.elements)


def _gate_message(
    outcome: dict[str, Any], validation: list["ValidationEntry"], time_confidence: float
) -> str:
    """One line: the gate decision with both validation mAPs (and both annotator speed-ups when measured, with how
    sure a saving is across the sites against the `time_confidence` asked), and what the validation sites were
    (their own rasters or reconstructions)."""
    from models.vma.validation import reconstructions

    candidate, current = outcome["candidate_metrics"], outcome["current_metrics"]
    verdict = "promoted" if outcome["promoted"] else "kept out by the gate"
    where = f"{len(validation)} validation site(s), {len(reconstructions(validation))} of them reconstructed"
    review = ""
    if "review" in candidate and "review" in current:
        new_s, old_s = candidate["review"]["correction_s"], current["review"]["correction_s"]
        review = (
            f"; simulated annotator {new_s:.0f} s vs {old_s:.0f} s before "
            f"({_speed_up(candidate['review'])} vs {_speed_up(current['review'])} faster than drawing)"
        )
        sure = review_saving_confidence(current["review"], candidate["review"])
        if new_s < old_s and sure is not None:
            review += f", a saving in {sure:.0%} of resamples of the sites ({time_confidence:.0%} needed)"
    return (
        f"{outcome['candidate']} {verdict}: validation mAP {candidate.get('mean_ap')} vs "
        f"{current.get('mean_ap')} before{review} on {where}; {outcome['labels']} labels, "
        f"{outcome['negatives']} negatives"
    )


def _speed_up(review: dict[str, Any]) -> str:
    return "n/a" if review.get("speed_up") is None else f"{review['speed_up']:.2f}x"


def validation_sites(settings: Settings) -> list["ValidationEntry"]:
    """The gate's validation sites: those scored on their own rasters, then the reconstructed ones (ValueError
    naming a site whose reconstruction is missing)."""
    from models.vma.validation import reconstruction_of

    return [
        *settings.vma_validation_sites,
        *(reconstruction_of(s) for s in settings.vma_validation_reconstructed),
    ]


def run_retrain(context: JobContext, params: RetrainParams, *, settings: Settings) -> JobResult:
    """Fine-tune the promoted model on the accepted/fixed elements (rejected ones as negatives) of every site in
    the database that has any (or of the job's site alone)."""
    from models.vma.config import TrainConfig
    from models.vma.retrain import LABEL_STATES, NEGATIVE_STATES, Corrections, RetrainConfig

    if settings.vma_registry is None:
        raise ValueError("retrain: no VMA registry configured (CAMA_VMA_REGISTRY)")
    sites = every_site_annotations(context) if params.every_site else [site_annotations(context)]
    corrections, names, labels, negatives = [], [], 0, 0
    for annotations, raster_dir, name in sites:
        view = training_view(annotations)
        site_labels = _count(view, LABEL_STATES)
        if site_labels == 0:
            continue
        corrections.append(Corrections(raster_dir, view))
        names.append(name)
        labels, negatives = labels + site_labels, negatives + _count(view, NEGATIVE_STATES)
    if labels == 0:
        where = "any site in the database" if params.every_site else f"site {sites[0][2]}"
        raise ValueError(f"retrain: no accepted, fixed or approved elements to learn from on {where}")
    context.report(
        0.05, f"retraining on {labels} labels and {negatives} negatives of {', '.join(names)}", force=True
    )
    config = RetrainConfig(
        train=TrainConfig(
            steps=params.steps, batch_size=params.batch_size, learning_rate=params.learning_rate
        ),
        tolerance=params.tolerance,
        time_tolerance=params.time_tolerance,
        time_confidence=params.time_confidence,
    )
    validation = validation_sites(settings)
    args = (
        settings.vma_registry,
        corrections,
        validation,
        config,
        params.annotator_gate,
        params.replay_share,
    )
    out = context.workdir / RETRAIN_FILE
    outcome = _run_child(context, args, out, stall_s=settings.retrain_stall_s)
    message = _gate_message(outcome, validation, params.time_confidence)
    if outcome["promoted"] and params.refresh_after_promotion:
        message += f"; proposal refresh queued as job {context.follow_up('refresh_proposals', {})}"
    return JobResult(out, message)


def run_refresh(context: JobContext, params: RefreshParams, *, settings: Settings) -> JobResult:
    """Propose again over the site's rasters and replace the proposals nobody has reviewed or edited."""
    from models.vma.checkpoint import checkpoint_kind
    from models.vma.element_masks.checkpoint import KIND as MASK_KIND
    from models.vma.propose import propose

    _annotations, raster_dir, name = site_annotations(context)
    learned = params.proposer == "learned" or (
        params.proposer == "auto" and settings.vma_registry is not None
    )
    if learned and settings.vma_registry is None:
        raise ValueError("refresh_proposals: the learned proposer needs a VMA registry (CAMA_VMA_REGISTRY)")
    context.report(0.05, f"proposing over {name} ({'learned' if learned else 'rule-based'})", force=True)
    out = context.workdir / PROPOSALS_FILE
    masks = (
        learned and settings.vma_registry is not None and checkpoint_kind(settings.vma_registry) == MASK_KIND
    )
    propose(
        raster_dir,
        out,
        proposer="masks" if masks else "learned" if learned else "rule",
        checkpoint=settings.vma_registry if learned else None,
        min_confidence=params.min_confidence,
        overwrite=True,
        show_progress=False,
    )
    proposals = AnnotationSet.read_json(out)
    context.report(0.8, f"{len(proposals.elements)} proposals; replacing untouched ones", force=True)
    threshold = settings.preaccept_threshold
    if threshold is None and learned and settings.vma_registry is not None:
        threshold = preaccept_threshold(settings.vma_registry)
    with context.session() as session:
        summary = refresh_proposals(
            session=session,
            site_id=context.site_id,
            proposals=proposals,
            username=LOOP_USER,
            threshold=threshold,
            qa_share=settings.qa_share,
            seed=context.job_id,
            margin_m=settings.extent_margin_m,
        )
    return JobResult(
        out,
        f"replaced {summary.replaced} untouched proposals by {summary.added} "
        f"({summary.preaccepted} pre-accepted, {summary.qa_sample} sampled for QA); "
        f"{summary.covered} already covered by kept elements, {summary.invalid} invalid",
    )


def unavailable_kinds(settings: Settings) -> dict[str, str]:
    """The loop's kinds this server cannot run as configured, with the reason (a 422 on submission)."""
    missing: dict[str, str] = {}
    if settings.vma_registry is None:
        missing["retrain"] = "not available: no VMA checkpoint registry configured (set CAMA_VMA_REGISTRY)"
    elif not settings.vma_validation_sites and not settings.vma_validation_reconstructed:
        missing["retrain"] = (
            "not available: no validation sites for the gate "
            "(set CAMA_VMA_VALIDATION_SITES or CAMA_VMA_VALIDATION_RECONSTRUCTED)"
        )
    return missing


def vma_job_kinds(settings: Settings) -> dict[str, JobKind]:
    """The loop's runnable kinds for these settings (see `unavailable_kinds` for the ones left out)."""
    kinds = {
        "refresh_proposals": JobKind(
            RefreshParams,
            partial(run_refresh, settings=settings),
            "Re-run the proposer and replace proposals nobody has reviewed or edited.",
        )
    }
    if "retrain" not in unavailable_kinds(settings):
        kinds["retrain"] = JobKind(
            RetrainParams,
            partial(run_retrain, settings=settings),
            "Fine-tune the model on the site's corrections; promote it if validation mAP does not drop.",
        )
    return kinds
