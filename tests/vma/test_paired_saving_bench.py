"""`bench/paired_saving.py` pairs two checkpoints' per-site correction times over the same sites and applies the
gate's confidence rule to them, per set and pooled; files it cannot pair are refused by name."""

import json
from pathlib import Path

import pytest

from bench.paired_saving import PairError, paired_sets


def results_file(path: Path, sites: list[str], times: list[float], checkpoint: str = "ckpt") -> Path:
    figures = {
        "sites": sites,
        "checkpoint": checkpoint,
        "settings": {"product": {"per_site_correction_s": times}},
    }
    path.write_text(json.dumps(figures), encoding="utf-8")
    return path


def test_a_saving_on_every_site_is_certain_and_one_lucky_site_is_not(tmp_path: Path) -> None:
    sites = [f"s{i}" for i in range(6)]
    current = results_file(tmp_path / "a.json", sites, [50.0] * 6)
    everywhere = results_file(tmp_path / "b.json", sites, [48.0] * 6, "candidate")
    one_site = results_file(tmp_path / "c.json", sites, [40.0] + [51.0] * 5)

    figures = paired_sets({"all": (current, everywhere)}, "product")
    row = figures["sets"]["all"]
    assert (row["current_total_s"], row["candidate_total_s"]) == (300.0, 288.0)
    assert (row["faster_sites"], row["slower_sites"]) == (6, 0)
    assert row["saving_confidence"] == 1.0
    assert row["checkpoints"] == ["ckpt", "candidate"]

    lucky = paired_sets({"one": (current, one_site)}, "product")["pooled"]
    assert lucky["candidate_total_s"] < lucky["current_total_s"]  # 295 s against 300 s in total
    assert (lucky["faster_sites"], lucky["slower_sites"]) == (1, 5)
    assert 0.2 < lucky["saving_confidence"] < 0.9


def test_sets_pool_their_sites(tmp_path: Path) -> None:
    first = (
        results_file(tmp_path / "a1.json", ["x"], [10.0]),
        results_file(tmp_path / "b1.json", ["x"], [12.0]),
    )
    second = (
        results_file(tmp_path / "a2.json", ["y", "z"], [10.0, 10.0]),
        results_file(tmp_path / "b2.json", ["y", "z"], [7.0, 7.0]),
    )
    pooled = paired_sets({"first": first, "second": second}, "product")["pooled"]
    assert pooled["sites"] == 3
    assert (pooled["current_total_s"], pooled["candidate_total_s"]) == (30.0, 26.0)
    assert (pooled["faster_sites"], pooled["slower_sites"]) == (2, 1)


def test_files_that_cannot_be_paired_are_refused_by_name(tmp_path: Path) -> None:
    current = results_file(tmp_path / "a.json", ["x", "y"], [10.0, 10.0])
    other_sites = results_file(tmp_path / "b.json", ["x", "z"], [9.0, 9.0])
    with pytest.raises(PairError, match="score different sites"):
        paired_sets({"set": (current, other_sites)}, "product")

    no_times = tmp_path / "c.json"
    no_times.write_text(
        json.dumps({"sites": ["x", "y"], "checkpoint": "c", "settings": {}}), encoding="utf-8"
    )
    with pytest.raises(PairError, match=r"c\.json: no 'product'"):
        paired_sets({"set": (current, no_times)}, "product")

    with pytest.raises(PairError, match=r"missing\.json: cannot read"):
        paired_sets({"set": (current, tmp_path / "missing.json")}, "product")

    twice = {"a": (current, current), "b": (current, current)}
    with pytest.raises(PairError, match="more than one set"):
        paired_sets(twice, "product")
