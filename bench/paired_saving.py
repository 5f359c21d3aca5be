"""Whether a candidate network saves the annotator time across many held-out sites, with the gate's own rule.

The settings benches (`bench/divider_carry.py` and its kin) score one checkpoint per run and record each site's
correction time (`per_site_correction_s`). Two such runs of the same sites, one per checkpoint, are paired here:
per set and over all sets pooled, both totals, how many sites each is faster on, and the confidence of a saving
(`models.vma.gate.saving_confidence`, the share of paired bootstrap resamples of the sites in which the
candidate's total is lower), which a server's retrain gate asks to be at least 0.9 before it promotes. Shipping a
network with the package is held to the same rule, over more sites than a gate has.

Usage: .venv/bin/python bench/paired_saving.py --pair NAME=CURRENT.json,CANDIDATE.json [--pair ...]
       [--setting product] [--out bench/results/paired_saving.json]
"""

import argparse
import json
import platform
import sys
from pathlib import Path
from typing import Any

from cama_pipeline.io import atomic_write_json
from models.vma.gate import saving_confidence

RESULTS = Path(__file__).parent / "results"


class PairError(ValueError):
    """Two results files that cannot be paired (named in the message)."""


def site_times(path: Path, setting: str) -> tuple[list[str], list[float], str]:
    """The sites, each one's correction time under `setting`, and the checkpoint of one results file."""
    try:
        figures = json.loads(Path(path).read_text(encoding="utf-8"))
        times = figures["settings"][setting]["per_site_correction_s"]
        return list(figures["sites"]), [float(t) for t in times], str(figures["checkpoint"])
    except (OSError, json.JSONDecodeError) as error:
        raise PairError(f"{path}: cannot read a results file ({error})") from error
    except KeyError as error:
        raise PairError(
            f"{path}: no {error} (settings.{setting}.per_site_correction_s, sites, checkpoint)"
        ) from error


def paired_set(current: Path, candidate: Path, setting: str) -> dict[str, Any]:
    """One set of sites scored by both checkpoints: totals, sites faster and slower, the saving's confidence."""
    sites, current_s, current_checkpoint = site_times(current, setting)
    candidate_sites, candidate_s, candidate_checkpoint = site_times(candidate, setting)
    if sites != candidate_sites:
        raise PairError(f"{current} and {candidate} score different sites")
    if len(current_s) != len(sites) or len(candidate_s) != len(sites):
        raise PairError(f"{current} or {candidate}: a time per site is missing")
    return {
        "files": [str(current), str(candidate)],
        "checkpoints": [current_checkpoint, candidate_checkpoint],
        "sites": sites,
        "current_s": current_s,
        "candidate_s": candidate_s,
        **saving_figures(current_s, candidate_s),
    }


def saving_figures(current_s: list[float], candidate_s: list[float]) -> dict[str, Any]:
    """Totals, the candidate's sites faster and slower, and the confidence of its saving."""
    return {
        "current_total_s": sum(current_s),
        "candidate_total_s": sum(candidate_s),
        "faster_sites": sum(b < a for a, b in zip(current_s, candidate_s, strict=True)),
        "slower_sites": sum(b > a for a, b in zip(current_s, candidate_s, strict=True)),
        "saving_confidence": saving_confidence(current_s, candidate_s),
    }


def paired_sets(pairs: dict[str, tuple[Path, Path]], setting: str) -> dict[str, Any]:
    """Every named set, and all of them pooled (each site once)."""
    sets = {name: paired_set(current, candidate, setting) for name, (current, candidate) in pairs.items()}
    pooled_sites = [site for figures in sets.values() for site in figures["sites"]]
    if len(set(pooled_sites)) != len(pooled_sites):
        raise PairError("a site is in more than one set; pooling would count it twice")
    current_s = [t for figures in sets.values() for t in figures["current_s"]]
    candidate_s = [t for figures in sets.values() for t in figures["candidate_s"]]
    return {"sets": sets, "pooled": {"sites": len(pooled_sites), **saving_figures(current_s, candidate_s)}}


def parse_pair(text: str) -> tuple[str, tuple[Path, Path]]:
    """`NAME=CURRENT.json,CANDIDATE.json` -> (name, (current, candidate))."""
    name, _, files = text.partition("=")
    paths = files.split(",")
    if not name or len(paths) != 2 or not all(paths):
        raise argparse.ArgumentTypeError(f"--pair {text!r}: expected NAME=CURRENT.json,CANDIDATE.json")
    return name, (Path(paths[0]), Path(paths[1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pair", type=parse_pair, action="append", required=True)
    parser.add_argument("--setting", default="product", help="the setting of the results files to pair")
    parser.add_argument("--out", type=Path, default=RESULTS / "paired_saving.json")
    args = parser.parse_args()
    try:
        figures = paired_sets(dict(args.pair), args.setting)
    except PairError as error:
        sys.exit(f"paired_saving: {error}")
    figures["command"] = "python " + " ".join(sys.argv)
    figures["machine"] = {"platform": platform.platform()}
    atomic_write_json(args.out, figures, indent=2)
    for name, row in {**figures["sets"], "pooled": figures["pooled"]}.items():
        print(
            f"{name}: {row['current_total_s']:.1f} s -> {row['candidate_total_s']:.1f} s, faster on "
            f"{row['faster_sites']}, slower on {row['slower_sites']}, confidence {row['saving_confidence']:.2f}"
        )
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
