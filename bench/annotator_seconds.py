"""Where the scripted annotator's seconds go on reconstructions: by element class and action, and why each fix was
needed.

The speed-up over drawing is one ratio; what would raise it is in the seconds behind it. On each `--site`'s
reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted network of
`--checkpoint` proposes once with the product's settings and the scripted annotator works its queue towards the
truth the cameras observed, in the reconstruction's frame, exactly as the retrain gate's `review_time` does (the
totals are the same figures). Then every second is booked to the class and action it went to: proposals accepted,
fixed or rejected (by the proposal's class), true elements drawn because no proposal covered them (by the true
class), and the scan of the road. Each fix says why the proposal was not accepted as it was: beyond the acceptance's
Chamfer distance, or within it but with a point farther than the acceptance's worst gap, and how far from the
nearer end of its line the farthest point either way lies. `ceilings` gives the speed-up if the fixes within the Chamfer
distance had been accepts, and if no true element had been left to draw. A checkpoint is refused on a site it saw.

Usage: .venv/bin/python bench/annotator_seconds.py --site data/synthetic/random-9211 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/annotator_seconds.json]
"""

import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from shapely.geometry import LineString, Point

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import Decision, Polyline, SimulationConfig, chamfer, farthest_point
from app.review_effort.review_time import MIN_CONFIDENCE, review_queue
from app.review_effort.session import (
    MemoryQueue,
    SessionLog,
    draw_from_scratch,
    drawn_seconds,
    work_queue,
)
from app.review_effort.truth import observed_true_polylines
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import (
    MaskInferenceConfig,
    predict_probabilities,
    vectors_from_probabilities,
)
from models.vma.rasters import load_site_rasters
from models.vma.validation import ValidationSite

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import settings_bench  # noqa: E402

RESULTS = Path(__file__).parent / "results"
END_BINS_M = (0.5, 2.0)
"""Where a fix's farthest point lies, in metres from the nearer end of its line: at the end vertex (within the
first bound), near the end (within the second), or inside the line."""


def _from_nearer_end(line: Polyline, point: np.ndarray) -> float:
    """Metres along `line` from its nearer end to `point` (on it)."""
    own = LineString(line.points)
    along = own.project(Point(point))
    return float(min(along, own.length - along))


def fix_reason(proposal: Polyline, truth: Polyline, config: SimulationConfig) -> dict[str, Any]:
    """Why a proposal matched to `truth` was fixed rather than accepted: its Chamfer distance and worst gap, whether
    it lay within the acceptance's Chamfer distance (so only the worst gap failed it), and which shape's point the
    worst gap is read at (`plan.farthest_point`, as the acceptance reads it) and its distance from the nearer end of
    that shape's line (None on a closed outline, a crossing, which has no ends)."""
    distance_chamfer = chamfer(proposal, truth)
    ways = {
        "proposal": (proposal, farthest_point(proposal, truth)),
        "truth": (truth, farthest_point(truth, proposal)),
    }
    side = max(ways, key=lambda name: ways[name][1][0])
    line, (gap_m, point) = ways[side]
    closed = truth.closed or proposal.closed
    return {
        "chamfer_m": round(distance_chamfer, 3),
        "worst_gap_m": round(gap_m, 3),
        "within_chamfer": distance_chamfer <= config.accept_m,
        "farthest_from_end_m": None if closed else round(_from_nearer_end(line, point), 2),
        "farthest_side": side,
    }


def _where(from_end_m: float | None) -> str:
    """Where a fix's farthest point lies: the `END_BINS_M` bin of a line, or the outline of a closed element."""
    end, near = END_BINS_M
    if from_end_m is None:
        return "on a closed outline"
    if from_end_m <= end:
        return f"at the end vertex (within {end} m of the end)"
    return (
        f"near the end ({end}-{near} m)"
        if from_end_m <= near
        else f"inside the line (over {near} m from an end)"
    )


def booked_seconds(
    queue: MemoryQueue,
    log: SessionLog,
    truths: list[Polyline],
    config: SimulationConfig,
    costs: ActionCosts,
) -> dict[str, Any]:
    """Every second of a worked `queue` booked to (class, action), and each fix's reason (`fix_reason`). The
    accepts, fixes and rejects are the queue's verdicts by the proposal's class; "drawn" are the true elements the
    annotator drew at the end (by their class); "scan" is the road scan, booked to no class. The booked seconds
    sum to the session's total."""
    booked = _tally()
    fixes = []
    for item, decision in queue.verdicts.items():
        proposal = queue.polyline(item)
        seconds = decision.seconds(costs)
        _add(booked[proposal.cls][decision.kind], seconds)
        if decision.kind == "fix" and decision.target is not None:
            fixes.append(
                {
                    "class": proposal.cls,
                    "seconds": round(seconds, 2),
                    **_edits(decision),
                    **fix_reason(proposal, truths[decision.target], config),
                }
            )
    for truth in queue.drawn:
        _add(booked[truth.cls]["drawn"], drawn_seconds(truth, config, costs))
    _add(booked["road"]["scan"], log.seconds["scan"])
    return {"booked": _plain(booked), "fixes": fixes}


def _tally() -> defaultdict[str, defaultdict[str, dict[str, float]]]:
    """Seconds and counts by class, then by action or reason, starting at zero."""
    return defaultdict(lambda: defaultdict(lambda: {"seconds": 0.0, "count": 0}))


def _add(entry: dict[str, float], seconds: float, count: int = 1) -> None:
    entry["seconds"] += seconds
    entry["count"] += count


def _plain(
    tally: defaultdict[str, defaultdict[str, dict[str, float]]],
) -> dict[str, dict[str, dict[str, float]]]:
    return {cls: dict(entries) for cls, entries in tally.items()}


def _edits(decision: Decision) -> dict[str, Any]:
    """The edits a fix took, as the cost model counts them."""
    return {
        "vertices_moved": decision.moved,
        "vertices_removed": decision.removed,
        "gaps_filled": len(decision.gap_runs),
        "pieces_merged": len(decision.merged),
        "moved_whole": decision.moved_whole,
        "split": decision.split_off is not None,
        "relabelled": decision.relabel is not None,
    }


def measure(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """The annotator's seconds on every site's proposals (the network run once a site), booked per site."""
    config, costs, inference = SimulationConfig(), ActionCosts(), MaskInferenceConfig()
    per_site = []
    for site in sites:
        rasters = load_site_rasters(site.rasters)
        truths = observed_true_polylines(site.site, rasters, site.frame)
        vectors = vectors_from_probabilities(
            rasters, predict_probabilities(model, rasters, inference), inference
        )
        _, queue = review_queue(vectors, MIN_CONFIDENCE)
        log = work_queue(queue, truths, config, costs)
        drawing_s = draw_from_scratch(MemoryQueue([]), truths, config, costs).total_s
        per_site.append(
            {
                "site": str(site.site),
                "correction_s": log.total_s,
                "drawing_s": drawing_s,
                **booked_seconds(queue, log, truths, config, costs),
            }
        )
        print(f"{site.site}: correction {log.total_s:.1f} s, drawing {drawing_s:.1f} s")
    return {"per_site": per_site}


def summary(figures: dict[str, Any]) -> dict[str, Any]:
    """The sites' seconds summed by class and action, the fixes by reason, and the speed-up ceilings."""
    per_site = figures["per_site"]
    correction_s = sum(s["correction_s"] for s in per_site)
    drawing_s = sum(s["drawing_s"] for s in per_site)
    booked = _tally()
    for site in per_site:
        for cls, actions in site["booked"].items():
            for action, entry in actions.items():
                _add(booked[cls][action], entry["seconds"], entry["count"])
    fixes = [fix for site in per_site for fix in site["fixes"]]
    reasons = _tally()
    for fix in fixes:
        within_or_beyond = "within" if fix["within_chamfer"] else "beyond"
        reason = (
            f"{within_or_beyond} the Chamfer distance; farthest point {_where(fix['farthest_from_end_m'])}"
        )
        _add(reasons[fix["class"]][reason], fix["seconds"])
    accept_s = Decision("accept").seconds(ActionCosts())
    within = [fix for fix in fixes if fix["within_chamfer"]]
    as_accepts_s = correction_s - sum(fix["seconds"] for fix in within) + accept_s * len(within)
    drawn_s = sum(actions["drawn"]["seconds"] for actions in booked.values() if "drawn" in actions)
    return {
        "correction_s": correction_s,
        "drawing_s": drawing_s,
        "speed_up": drawing_s / correction_s if correction_s > 0 else None,
        "booked": _plain(booked),
        "fix_reasons": _plain(reasons),
        "ceilings": {
            "fixes_within_chamfer_accepted": {
                "correction_s": as_accepts_s,
                "speed_up": drawing_s / as_accepts_s if as_accepts_s > 0 else None,
            },
            "nothing_left_to_draw": {
                "correction_s": correction_s - drawn_s,
                "speed_up": drawing_s / (correction_s - drawn_s) if correction_s > drawn_s else None,
            },
        },
        "per_site": per_site,
    }


def main() -> None:
    settings_bench(
        "bench/annotator_seconds.py",
        __doc__.splitlines()[0],
        RESULTS / "annotator_seconds.json",
        measure,
        summary,
    )


if __name__ == "__main__":
    main()
