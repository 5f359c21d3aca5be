"""README's figures agree with the results files the benchmarks wrote (issue 20, point 6).

Each checked table is found by its header and by the paragraph above it, which must name the results file and the
bench script that wrote it. Every figure is compared at the precision README prints it: the JSON value is
formatted with as many decimals as the figure in the cell has, figure by figure in the order the cell shows them.
SRE is checked at 960x540 (`sre_ref_px`), the paper's and CAMA's scale.
"""

import json
import re
import statistics
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from cama_pipeline.surface import SurfaceConfig
from models.vma.element_masks.propose import MaskInferenceConfig
from models.vma.gate import TIME_CONFIDENCE, saving_confidence

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "bench" / "results"

NUMBER = re.compile(r"(?<![\w.])-?\d[\d,]*(?:\.\d+)?")
"""A figure as README prints it: digits with thousands commas and decimals, not glued to a word (p95, c1)."""
RESULTS_PATH = re.compile(r"bench/results/[\w./-]*[\w/]")

Expected = float | int | None
"""A figure's value; None skips that figure of the cell."""


@dataclass(frozen=True)
class MarkdownTable:
    """A README table: its header cells, its rows by first cell, and the paragraph right above it."""

    header: list[str]
    rows: dict[str, list[str]]
    context: str


@cache
def readme_text() -> str:
    return README.read_text(encoding="utf-8")


@cache
def results(name: str) -> dict[str, Any]:
    return json.loads((RESULTS / name).read_text(encoding="utf-8"))


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def tables(text: str) -> list[MarkdownTable]:
    """Every pipe table of `text`, with the paragraph (lines up to the previous blank line) above it."""
    lines = text.splitlines()
    found, i = [], 0
    while i < len(lines):
        if not lines[i].startswith("|"):
            i += 1
            continue
        start = i
        while i < len(lines) and lines[i].startswith("|"):
            i += 1
        block = lines[start:i]
        above = start - 1
        while above >= 0 and not lines[above].strip():
            above -= 1
        top = above
        while top >= 0 and lines[top].strip():
            top -= 1
        rows = {_cells(line)[0]: _cells(line) for line in block[2:]}
        found.append(MarkdownTable(_cells(block[0]), rows, "\n".join(lines[top + 1 : above + 1])))
    return found


def table(first_header: str, context_has: str = "") -> MarkdownTable:
    """The one table whose first header cell is `first_header` and whose paragraph contains `context_has`."""
    matches = [t for t in tables(readme_text()) if t.header[0] == first_header and context_has in t.context]
    assert len(matches) == 1, f"README: {len(matches)} tables headed {first_header!r} after {context_has!r}"
    return matches[0]


def figures(cell: str) -> list[str]:
    return [token.replace(",", "") for token in NUMBER.findall(cell)]


def assert_shows(cell: str, expected: list[Expected], where: str) -> None:
    """The cell's first figures are the expected values, each rounded as README prints it."""
    shown = figures(cell)
    assert len(shown) >= len(expected), f"{where}: {cell!r} shows {shown}, expected {len(expected)} figures"
    for token, value in zip(shown, expected, strict=False):
        if value is None:
            continue
        decimals = len(token.split(".")[1]) if "." in token else 0
        assert f"{value:.{decimals}f}" == token, (
            f"{where}: README shows {token} in {cell!r}; the results file says {value!r}"
        )


def row(t: MarkdownTable, label: str) -> list[str]:
    assert label in t.rows, f"README table after {t.context[:60]!r}: no row {label!r}"
    return t.rows[label]


def assert_names_source(t: MarkdownTable, results_file: str, script: str) -> None:
    assert f"bench/results/{results_file}" in t.context, (
        f"table after {t.context!r} does not name {results_file}"
    )
    assert script in t.context, f"table after {t.context!r} does not name the command ({script})"


def row_starting(t: MarkdownTable, prefix: str) -> tuple[str, list[str]]:
    """The one row whose label starts with `prefix` (labels end with counts the results give), and its cells."""
    (label,) = [label for label in t.rows if label.startswith(prefix)]
    return label, t.rows[label]


def assert_shows_saving(cell: str, against: dict[str, Any], where: str) -> None:
    """A cell showing a setting's correction ratio and saving confidence (`bench.vma_measures.against_baseline`)."""
    assert_shows(cell, [against["correction_ratio"], against["saving_confidence"]], where)


def recorded_rows(
    t: MarkdownTable, files: dict[str, str], script: str
) -> Iterator[tuple[str, str, list[str], dict[str, Any]]]:
    """For each row label's start -> results file: the file and `script` named above the table, then the row's
    start, its label, its cells and the recorded figures."""
    for prefix, name in files.items():
        assert_names_source(t, name, script)
        label, cells = row_starting(t, prefix)
        yield prefix, label, cells, results(name)


def assert_seeds(recorded: dict[str, Any], seeds: Iterable[int]) -> None:
    """The results file measured exactly the randomised sites of these seeds, in order."""
    assert [site.rsplit("-", 1)[-1] for site in recorded["sites"]] == [str(seed) for seed in seeds]


HELD_OUT_SETS = {
    "gate 9113-9123": "gate",
    "fresh 9201-9210": "fresh",
    "fresh 9211-9220": "fresh2",
    "fresh 9221-9230": "fresh3",
    "confirmation, six sites": "confirm",
    "gate validation 9007, 9011": "9007_9011",
}
"""Row label's start -> results file suffix of the tables measured on the gate reconstructions and five held-out
sets (the boundary offset, the editor's split, the divider carry)."""


def set_files(stem: str) -> dict[str, str]:
    """Row label's start -> results file of a bench run on the gate and held-out sets (`HELD_OUT_SETS`)."""
    return {prefix: f"{stem}_{suffix}.json" for prefix, suffix in HELD_OUT_SETS.items()}


def assert_shows_boundaries(cell: str, shown: dict[str, Any], where: str) -> None:
    """A cell showing a boundary setting's accepted share, vertices off, correction seconds and speed-up
    (`bench/boundary_evidence.py`'s `setting_figures`)."""
    assert_shows(
        cell,
        [shown["acceptable_share"], shown["vertices_off_share"], shown["correction_s"], shown["speed_up"]],
        where,
    )


def test_every_results_file_named_exists() -> None:
    named = {m.group(0).rstrip("/.") for m in RESULTS_PATH.finditer(readme_text())}
    assert named
    missing = sorted(p for p in named if not (ROOT / p).exists())
    assert not missing, f"README names results files that do not exist: {missing}"


SRE_ROWS_BASELINE = {
    "ground-truth 3D map, true poses": "a_gt3d_true_poses",
    "baseline 2D map (no z, offset, rule-based divider), logged coarse poses": "b_baseline2d_coarse_poses",
}
SRE_ROWS_END_TO_END = {
    "(a) true 3D map, true poses": "a_truth",
    "(b) baseline 2D map, coarse poses": "b_baseline_2d",
    "(c1) pipeline proposals as they are, SfM poses": "c1_proposals",
    "(c2) pipeline after the simulated correction pass, SfM poses": "c2_corrected",
}


def _sre_figures(summary: dict[str, Any]) -> list[Expected]:
    return [summary["sre_ref_px"], summary["precision"], summary["recall"], summary["f1"]]


def test_sre_baseline_table_at_960x540() -> None:
    t = table("map (default synthetic site)")
    assert_names_source(t, "sre_baseline.json", "bench/sre_baseline.py")
    assert "960x540" in t.header[1] and "sre_ref_px" in t.header[1]
    recorded = results("sre_baseline.json")
    for label, key in SRE_ROWS_BASELINE.items():
        cells = row(t, label)
        assert_shows(" | ".join(cells[1:5]), _sre_figures(recorded[key]["overall"]), f"SRE row {label!r}")


def test_end_to_end_sre_table_at_960x540() -> None:
    t = table("map", "SRE")
    assert_names_source(t, "end_to_end.json", "bench/end_to_end.py")
    assert "960x540" in t.header[1] and "sre_ref_px" in t.header[1]
    recorded = results("end_to_end.json")["sre"]
    for label, key in SRE_ROWS_END_TO_END.items():
        cells = row(t, label)
        assert_shows(" | ".join(cells[1:5]), _sre_figures(recorded[key]), f"end-to-end SRE row {label!r}")


VMA_ROWS = {
    "rule-based": "rule_based",
    "learned v0003, rescored (shipped)": "learned",
    "learned v0003, its own points": "learned_refined",
    "free-query MapTR v0001": "learned_free",
}


def test_vma_chamfer_ap_table() -> None:
    t = table("proposer", "bench/vma.py")
    assert_names_source(t, "vma.json", "bench/vma.py")
    recorded = results("vma.json")["results"]
    for label, key in VMA_ROWS.items():
        expected = [recorded["clean"][key]["mean_ap"], recorded["degraded"][key]["mean_ap"]]
        assert_shows(" | ".join(row(t, label)[1:3]), expected, f"VMA row {label!r}")


def test_vma_confidence_bins() -> None:
    bins = results("vma.json")["results"]["degraded"]["learned"]["confidence_bins"]
    shown = ", ".join(f"{b['precision']:.2f}" for b in bins)
    assert f"({shown} for [0, .25)" in " ".join(readme_text().split())


SURFACE_ROWS = {
    "true": "ground_truth",
    "SfM": "sfm",
    "WIGO": "wigo",
    "true, vote alone (no refinement)": "vote:ground_truth",
    "SfM, vote alone (no refinement)": "vote:sfm",
    "SfM, flat (no kerb step)": "ablation_no_kerb_step",
    "SfM, kerb foot relabelled": "variant_kerb_foot",
    "true, refined, without the curvature prior, SfM gate and curb-height vote": (
        "baseline_no_prior_no_gate_no_curb_height_gt_poses"
    ),
}


def _surface_figures(run: dict[str, Any]) -> list[Expected]:
    iou, kerb = run["iou"], run["kerb"]
    return [
        run["elevation_rmse_m"] * 100,
        kerb["elevation_rmse_m_road_and_curb"] * 100,
        kerb["elevation_rmse_m_curb_cells"] * 100,
        iou["road"],
        iou["curb"],
        iou["lane_marking"],
        iou["crosswalk"],
        run["psnr_db"],
        run["seconds"]["elevation"],
        run["seconds"]["refine"],
        run["seconds"]["observe"],
    ]


def _surface_run(recorded: dict[str, Any], key: str) -> dict[str, Any]:
    """A run of bench/surface.py's results: a pose source of `runs` or (`vote:<poses>`) of `vote_runs`, or a
    top-level variant."""
    if key.startswith("vote:"):
        return next(run for run in recorded["vote_runs"] if run["poses"] == key.removeprefix("vote:"))
    by_poses = {run["poses"]: run for run in recorded["runs"]}
    return by_poses[key] if key in by_poses else recorded[key]


@pytest.mark.parametrize(
    ("first_header", "results_file", "labels"),
    [
        ("poses", "surface.json", list(SURFACE_ROWS)),
        (
            "poses, site 9011",
            "surface_9011.json",
            [*list(SURFACE_ROWS)[:2], *list(SURFACE_ROWS)[3:5], "SfM, kerb foot relabelled"],
        ),
    ],
)
def test_surface_tables(first_header: str, results_file: str, labels: list[str]) -> None:
    t = table(first_header, "bench/surface.py")
    assert_names_source(t, results_file, "bench/surface.py")
    recorded = results(results_file)
    for label in labels:
        run = _surface_run(recorded, SURFACE_ROWS[label])
        assert_shows(" | ".join(row(t, label)[1:]), _surface_figures(run), f"surface row {label!r}")
    gains = {gain["poses"]: gain for gain in recorded["refine_vs_vote"]}
    for poses in ("ground_truth", "sfm"):
        refined, vote = _surface_run(recorded, poses), _surface_run(recorded, f"vote:{poses}")
        assert (
            gains[poses]["iou_gain"]["lane_marking"]
            == refined["iou"]["lane_marking"] - vote["iou"]["lane_marking"]
        )


SPLIT_ROWS = {
    "fitted (vote alone)": "vote",
    "refined (the stage)": "refined",
    "true road elevation": "true_road",
    "true surface (kerbs raised)": "true_surface",
}


@pytest.mark.parametrize(
    ("first_header", "results_file"),
    [("surface, default site", "surface_split.json"), ("surface, site 9011", "surface_split_9011.json")],
)
def test_surface_split_tables(first_header: str, results_file: str) -> None:
    t = table(first_header, "bench/surface_split.py")
    assert_names_source(t, results_file, "bench/surface_split.py")
    runs = results(results_file)["runs"]
    for label, key in SPLIT_ROWS.items():
        run = runs[key]
        iou = run["iou"]
        expected = [
            run["elevation_rmse_m"] * 100,
            iou["road"],
            iou["curb"],
            iou["lane_marking"],
            iou["crosswalk"],
        ]
        assert_shows(" | ".join(row(t, label)[1:]), [*expected, run["psnr_db"]], f"split row {label!r}")


SFM_ROWS = {
    "(a) pycolmap incremental mapping": "a_incremental",
    "(b) guided + plain BA": "b_plain",
    "(c) + rigid BA": "c_rigid",
    "(d) + iterative BA": "d_iterative",
    "(e) parallel clips + merge": "e_parallel",
}


def _sfm_figures(method: dict[str, Any], with_shape: bool = True) -> list[Expected]:
    """Wall / CPU s, position / rotation, reprojection, registered and, where README shows it, shape only."""
    figures = [method["seconds"], method["cpu_seconds"], method["position_cm"], method["rotation_deg"]]
    figures += [method["reprojection_error_px"], method["registered_ratio"]]
    return figures + [method["gauge_free"]["position_cm"]] if with_shape else figures


@pytest.mark.parametrize(
    ("site", "run_key", "h_file"),
    [
        ("default", "default:scene-0001,scene-0002,scene-0003", "sfm_scale_gauge.json"),
        (
            "large",
            "large:scene-0001,scene-0002,scene-0003,scene-0004,scene-0005,scene-0006",
            "sfm_large_scale_gauge.json",
        ),
    ],
)
def test_sfm_tables(site: str, run_key: str, h_file: str) -> None:
    t = table("method", f"bench/sfm.py --site data/synthetic/{site}")
    assert_names_source(t, "sfm.json", "bench/sfm.py")
    methods = results("sfm.json")["runs"][run_key]["methods"]
    for label, key in SFM_ROWS.items():
        expected = _sfm_figures(methods[key], with_shape=key != "a_incremental")  # (a): no shape-only figure
        assert_shows(" | ".join(row(t, label)[1:]), expected, f"sfm {site} row {label!r}")
    wigo = methods["wigo"]
    assert_shows(
        " | ".join(row(t, "WIGO coarse poses")[2:]),
        [wigo["position_cm"], wigo["rotation_deg"], wigo["registered_ratio"]],
        f"sfm {site} WIGO row",
    )
    h_row = next(label for label in t.rows if label.startswith("(h)"))
    h = results(h_file)["runs"][run_key]["methods"]["h_parallel_scale_gauge"]
    assert_shows(
        " | ".join(row(t, h_row)[1:]), _sfm_figures(h, with_shape=site == "large"), f"sfm {site} (h)"
    )


def test_sfm_placement_table() -> None:
    t = table("site", "bench/sfm_placement.py")
    assert_names_source(t, "sfm_placement.json", "bench/sfm_placement.py")
    for site, run in results("sfm_placement.json")["runs"].items():
        rows = run["rows"]
        clips = run["clip_scale_to_truth"].values()
        expected = [
            rows["as_written"]["position_cm"],
            rows["model_at_true_scale_rigid_gauge"]["position_cm"],
            rows["true_shape_rigid_gauge"]["position_cm"],
            rows["true_shape_scaled_gauge"]["position_cm"],
            run["model_scale_to_truth"],
            min(clips),
            max(clips),
        ]
        assert_shows(" | ".join(row(t, site)[1:]), expected, f"sfm placement row {site!r}")


PAIRS_ROWS = {
    "exhaustive": "exhaustive",
    "sequential": "sequential",
    "sequential + HSP (40 m, 40 % overlap, repeats)": "sequential+hsp",
}


def test_pairs_table() -> None:
    t = table("strategy")
    assert_names_source(t, "pairs.json", "bench/pairs.py")
    sites = results("pairs.json")["sites"]
    for label, key in PAIRS_ROWS.items():
        expected: list[Expected] = []
        for site in ("data/synthetic/default", "data/synthetic/large"):
            strategy = sites[site]["site-001"][key]
            cpu = strategy["estimated_matching_cpu_seconds"]["blas"]
            expected += [
                strategy["pairs"],
                strategy["share_of_exhaustive"] * 100,
                strategy["recall"]["mutual>=0.5"],
            ]
            expected += [cpu] + ([cpu / 3600] if key == "exhaustive" and site.endswith("large") else [])
        assert_shows(" | ".join(row(t, label)[1:]), expected, f"pairs row {label!r}")


API_ROWS = {
    "SQLite, current": ("sqlite", False),
    "SQLite, commit 1ddf7a8": ("sqlite", True),
    "PostgreSQL, current": ("postgresql", False),
    "PostgreSQL, commit 1ddf7a8": ("postgresql", True),
}


def test_api_load_table() -> None:
    t = table("server")
    assert_names_source(t, "api_load.json", "bench/api_load.py")
    recorded = results("api_load.json")
    for label, (database, baseline) in API_ROWS.items():
        server = recorded[database]["baseline"] if baseline else recorded[database]
        paced, saturation = server["paced"], server["saturation"]
        expected = [
            paced["p50_ms"],
            paced["p99_ms"],
            saturation["throughput_edits_per_s"],
            paced["server_cpu_ms_per_edit"],
        ]
        assert_shows(" | ".join(row(t, label)[1:]), expected, f"API row {label!r}")


def test_api_lint_table() -> None:
    t = table("lint, 60 x 5,000-vertex site")
    assert_names_source(t, "api_load.json", "bench/api_load.py")
    recorded = results("api_load.json")["lint"]
    assert f"--baseline-ref {recorded['config']['baseline_ref']}" in t.context
    rows = {
        "current": recorded["current"],
        f"commit {recorded['config']['baseline_ref']}": recorded["baseline"],
    }
    for label, figures_of in rows.items():
        expected = [
            figures_of["first_lint_s"],
            figures_of["first_lint_server_cpu_s"],
            figures_of["warm_lint_ms"],
            figures_of["edit_lint_ms"],
        ]
        assert_shows(" | ".join(row(t, label)[1:]), expected, f"lint row {label!r}")


def test_end_to_end_measures_table() -> None:
    t = table("measure")
    assert_names_source(t, "end_to_end.json", "bench/end_to_end.py")
    e2e = results("end_to_end.json")
    stages, reports = e2e["stage_seconds"], e2e["stage_reports"]
    stage_figures = [stages[s] for s in ("wigo", "keyframes", "sites", "pairs")] + [stages["features"] / 60]
    stage_figures += [reports["features"]["extract"], reports["features"]["match"], stages["sfm"]]
    stage_figures += [reports["sfm"]["clips"], reports["sfm"]["merge"], stages["surface"], stages["propose"]]
    assert_shows(row(t, "time per stage (first run)")[1], stage_figures, "end-to-end time per stage")
    wigo, sfm = e2e["poses"]["wigo"], e2e["poses"]["sfm"]
    assert_shows(
        row(t, "camera poses, absolute")[1],
        [wigo["position_cm"], wigo["rotation_deg"], sfm["position_cm"], sfm["rotation_deg"]],
        "end-to-end poses",
    )
    assert_shows(
        row(t, "camera poses, shape only")[1],
        [
            wigo["gauge_free_position_cm"],
            wigo["gauge_free_rotation_deg"],
            sfm["gauge_free_position_cm"],
            sfm["gauge_free_rotation_deg"],
        ],
        "end-to-end poses, shape only",
    )
    elevation = e2e["elevation"]
    assert_shows(
        row(t, "elevation (SfM poses + points), observed road cells")[1],
        [elevation["rmse_cm"], elevation["median_abs_cm"], elevation["p95_abs_cm"]],
        "end-to-end elevation",
    )
    observed, everything = e2e["proposals_ap"]["observed_truth"], e2e["proposals_ap"]["all_truth"]
    classes = observed["class_ap"]
    assert_shows(
        row(t, "VMA proposals on the reconstructed rasters, Chamfer mAP")[1],
        [
            observed["mean_ap"],
            classes["divider"],
            classes["ped_crossing"],
            classes["boundary"],
            everything["mean_ap"],
        ],
        "end-to-end proposals",
    )
    annotator = e2e["annotator"]
    counts = annotator["corrected"]["counts"]
    assert_shows(
        row(t, "simulated annotator, person-hours per km of observed road")[1],
        [
            annotator["scratch"]["hours_per_km"],
            annotator["corrected"]["hours_per_km"],
            annotator["speed_up"],
            counts["accept"],
            counts["fix"],
            counts["reject"],
            counts["drawn"],
            counts["gaps_drawn"],
        ],
        "end-to-end annotator",
    )


EXPORT_ROWS = {
    "true 3D map, true poses": "ref",
    "(a) true 3D map, exported odometry (refined)": "a_truth",
    "true 3D map, SfM poses directly": "a_truth_sfm",
    "true 3D map, exported odometry moved rigidly onto the true poses (diagnostic)": "a_truth_placed",
    "true map as exported (labels, elevation raster, per-scene cut), exported odometry": "a_truth_labels",
    "(b) true 3D map, coarse odometry (`--poses coarse`)": "b_truth_coarse",
    "(c) pipeline proposals as exported, exported odometry": "c_pipeline",
    "pipeline proposals exported without the per-scene cut, exported odometry": "c_uncut",
    "pipeline proposals before export, SfM poses directly": "c_sfm",
}


def test_export_table_both_protocols() -> None:
    t = table("export row")
    assert_names_source(t, "export.json", "bench/export.py")
    recorded = results("export.json")
    for label, key in EXPORT_ROWS.items():
        cells = row(t, label)
        assert_shows(
            " | ".join(cells[1:5]), _sre_figures(recorded["strict"][key]), f"export strict {label!r}"
        )
        assert_shows(" | ".join(cells[5:9]), _sre_figures(recorded["cama"][key]), f"export cama {label!r}")


SIFT_OCTAVE_RUNS = {
    "tiny site: -1": "end_to_end_1600_octave_minus_1.json",
    "tiny site: per width (0)": "end_to_end_1600_per_width.json",
    "9401: -1": "end_to_end_1600_9401_octave_minus_1.json",
    "9401: per width (0)": "end_to_end_1600_9401_per_width.json",
}


def test_sift_octave_table() -> None:
    """The whole path at 1600x900 with SIFT's first octave forced to -1 and chosen per width, on two sites: every
    cell its run's figure, each run of the product's predicted masks and element-mask network."""
    t = table("whole path at 1600x900, mask-free, by SIFT's first octave", "bench/end_to_end.py")
    for column, name in SIFT_OCTAVE_RUNS.items():
        assert_names_source(t, name, "bench/end_to_end.py")
        run = results(name)
        assert run["first_octave"] == (-1 if column.endswith(": -1") else "per width")
        assert "--masks predicted --proposer masks" in run["command"]
        index = t.header.index(column)
        expected: dict[str, list[Expected]] = {
            f"{stage} (s per key frame)": [run["stage_seconds_per_keyframe"][stage]]
            for stage in NATIVE_RESOLUTION_STAGES
        }
        expected["whole path (s per key frame)"] = [sum(run["stage_seconds"].values()) / run["keyframes"]]
        expected["SfM position error, gauge-free (cm)"] = [run["poses"]["sfm"]["gauge_free_position_cm"]]
        expected["elevation RMSE (cm)"] = [run["elevation"]["rmse_cm"]]
        ap = run["proposals_ap"]
        expected["proposal mAP, all truth / observed truth"] = [
            ap["all_truth"]["mean_ap"],
            ap["observed_truth"]["mean_ap"],
        ]
        expected["scripted annotator, speed-up over drawing: world / own frame"] = [
            run["annotator"]["speed_up"],
            run["annotator_in_reconstruction_frame"]["speed_up"],
        ]
        expected["SRE 960x540 of the proposals (px)"] = [run["sre"]["c1_proposals"]["sre_ref_px"]]
        for label, values in expected.items():
            assert_shows(row(t, label)[index], values, f"SIFT octave {column} {label!r}")
    # the prose's reading: SIFT at the images' own scale takes 0.41 of the time on both sites
    for site in ("tiny site", "9401"):
        before = results(SIFT_OCTAVE_RUNS[f"{site}: -1"])["stage_seconds_per_keyframe"]["features"]
        after = results(SIFT_OCTAVE_RUNS[f"{site}: per width (0)"])["stage_seconds_per_keyframe"]["features"]
        assert round(after / before, 2) == 0.41, site


def test_sift_octave_annotator_booking_sentence() -> None:
    """The own-frame annotator's loss per width, booked by class: one divider on the tiny site, one crossing on
    9401, each worth the seconds the prose gives."""
    runs = {
        run["site"].rsplit("/", 1)[1]: run
        for run in results("annotator_seconds_1600_octave.json")["per_site"]
    }

    def seconds(folder: str, cls: str) -> float:
        return sum(action["seconds"] for action in runs[folder]["booked"][cls].values())

    def counts(folder: str, cls: str) -> dict[str, int]:
        return {action: entry["count"] for action, entry in runs[folder]["booked"][cls].items()}

    tiny, fresh = "oct-tiny-1600-", "oct-tiny-random-1600-9401-"
    assert counts(tiny + "octave-minus-1", "divider") == {"accept": 7, "fix": 1}
    assert counts(tiny + "per-width", "divider") == {"accept": 7, "reject": 1, "drawn": 1}
    assert counts(fresh + "octave-minus-1", "ped_crossing") == {"fix": 3, "accept": 1}
    assert counts(fresh + "per-width", "ped_crossing") == {"fix": 4}
    before = runs[tiny + "octave-minus-1"]["booked"]["divider"]["fix"]["seconds"]
    after = sum(runs[tiny + "per-width"]["booked"]["divider"][a]["seconds"] for a in ("reject", "drawn"))
    more = seconds(fresh + "per-width", "ped_crossing") - seconds(fresh + "octave-minus-1", "ped_crossing")
    text = " ".join(readme_text().split())
    assert (
        f"one divider fixed as proposed ({before:.1f} s) is rejected and drawn per width ({after:.1f} s), and on "
        f"9401 one crossing accepted as proposed is fixed per width ({more:.1f} s more)"
    ) in text


NATIVE_RESOLUTION_STAGES = ("segment", "features", "sfm", "surface")


def test_native_resolution_table_from_both_runs() -> None:
    t = table("whole path, tiny site, predicted masks")
    assert_names_source(t, "end_to_end_1600.json", "bench/end_to_end.py")
    assert "bench/results/end_to_end_256.json" in t.context
    low, high = results("end_to_end_256.json"), results("end_to_end_1600.json")

    def per_keyframe_total(run: dict[str, Any]) -> float:
        return float(sum(run["stage_seconds"].values()) / run["keyframes"])

    def quality(run: dict[str, Any]) -> list[float]:
        return [
            run["poses"]["sfm"]["position_cm"],
            run["elevation"]["rmse_cm"],
            run["proposals_ap"]["all_truth"]["mean_ap"],
            run["proposals_ap"]["observed_truth"]["mean_ap"],
            run["annotator"]["speed_up"],
            run["sre"]["c1_proposals"]["sre_ref_px"],
        ]

    for run in (low, high):  # today's product: predicted masks, the element-mask network
        assert "--masks predicted --proposer masks" in run["command"] and run["proposer"] == "masks"

    measured = {
        **{
            f"{stage} (s per key frame)": (
                low["stage_seconds_per_keyframe"][stage],
                high["stage_seconds_per_keyframe"][stage],
            )
            for stage in NATIVE_RESOLUTION_STAGES
        },
        "whole path (s per key frame)": (per_keyframe_total(low), per_keyframe_total(high)),
        "peak memory, main process (MB)": (low["peak_memory"]["self_mb"], high["peak_memory"]["self_mb"]),
        "peak memory, largest worker (MB)": (
            low["peak_memory"]["largest_child_mb"],
            high["peak_memory"]["largest_child_mb"],
        ),
    }
    for label, (small, large) in measured.items():
        cells = row(t, label)
        assert_shows(" | ".join(cells[1:4]), [small, large, large / small], f"native resolution {label!r}")
    labels = [
        "SfM position error (cm)",
        "elevation RMSE (cm)",
        "proposal mAP",
        "proposal mAP, observed truth",
        "scripted annotator, speed-up over drawing",
        "SRE 960x540 of the proposals (px)",
    ]
    for label, small, large in zip(labels, quality(low), quality(high), strict=True):
        assert_shows(" | ".join(row(t, label)[1:3]), [small, large], f"native resolution {label!r}")


SEGMENT_SITES = {
    "9001 (tuning)": "segment.json",
    "9002 (confirmation)": "segment_9002.json",
    "9003, default size (confirmation)": "segment_default_9003.json",
}


def test_segmentation_iou_table_from_both_sites() -> None:
    t = table("class", "bench/results/segment_9002.json")
    assert_names_source(t, "segment.json", "bench/segment.py")
    for column, name in SEGMENT_SITES.items():
        index = t.header.index(column)
        figures_of = results(name)["segmentation"]
        for label, cells in t.rows.items():
            key = label.replace(" ", "_")
            expected = [figures_of["per_class_iou"][key], figures_of["network_per_class_iou"][key]]
            assert_shows(cells[index], expected, f"segmentation {column} {label!r}")


def test_segmentation_whole_path_table_from_both_sites() -> None:
    t = table("run", "bench/results/segment_9002.json")
    assert_names_source(t, "segment.json", "bench/segment.py")
    for site, name in (
        ("9001", "segment.json"),
        ("9002", "segment_9002.json"),
        ("9003", "segment_default_9003.json"),
    ):
        for run_label, key in (
            ("generator masks", "generator_masks"),
            ("predicted masks", "predicted_masks"),
        ):
            run = results(name)["runs"][key]
            expected = [
                run["poses"]["sfm"]["position_cm"],
                run["elevation"]["rmse_cm"],
                run["bev_iou"]["lane_marking"],
                run["proposals_ap"]["observed_truth"]["mean_ap"],
                run["sre"]["sre_ref_px"],
                run["annotator_speed_up"],
            ]
            cells = row(t, f"{site}, {run_label}")
            assert_shows(" | ".join(cells[1:]), expected, f"segmentation whole path {site} {run_label}")


def _loop_figures(figures: dict[str, Any]) -> list[Expected]:
    return [figures["map_clean"], figures["map_damaged"], figures["annotator"]["speed_up"]]


def test_vma_loop_rounds_table() -> None:
    t = table("round", "bench/vma_loop.py")
    assert_names_source(t, "vma_loop.json", "bench/vma_loop.py")
    recorded = results("vma_loop.json")
    for entry in recorded["rounds"]:
        label = next(name for name in t.rows if name.split(" ")[0] == str(entry["round"]))
        cells = row(t, label)
        heldout = entry["heldout"]
        assert heldout["version"] in cells[1], f"round {entry['round']}: promoted {heldout['version']}"
        if "retrain_seconds" in entry:
            assert_shows(cells[2], [entry["retrain_seconds"]], f"round {entry['round']} seconds")
        assert_shows(cells[3], _loop_figures(heldout), f"round {entry['round']} rescored")
        assert_shows(cells[4], _loop_figures(heldout["own_points"]), f"round {entry['round']} own points")
    assert_shows(row(t, "rule-based")[3], _loop_figures(recorded["rule_based"]), "rule-based")


def test_kerb_step_annotator_figures() -> None:
    text = " ".join(readme_text().split())
    speed = {
        name: results(f"end_to_end_kerb_{name}.json")["annotator"]["speed_up"] for name in ("step", "foot")
    }
    assert f"went from {speed['step']:.2f}x to {speed['foot']:.2f}x with it" in text
    flat = results("end_to_end_kerb_flat.json")["annotator"]["speed_up"]
    assert f"({flat:.2f}x with and without;" in text and f"{flat:.2f}" == f"{speed['step']:.2f}"
    maps = {
        f"{results(f'end_to_end_kerb_{n}.json')['proposals_ap']['observed_truth']['mean_ap']:.2f}"
        for n in ("step", "foot", "flat")
    }
    assert maps == {"0.91"} and "proposal mAP 0.91 in all three" in text


def test_kerb_foot_width_figures() -> None:
    """The one-width kerb foot: its curb figures from bench/surface.py's foot variant, its end-to-end runs against
    the refinement-on runs without it."""
    text = " ".join(readme_text().split())
    default, site_9011 = results("surface.json"), results("surface_9011.json")
    sfm = _surface_run(default, "sfm")
    foot = default["variant_kerb_foot"]
    lost, lost_foot = sfm["curb_confusion"], foot["curb_confusion"]
    assert (
        f"(`curb_confusion.true_curb_labelled_road` in `bench/results/surface.json`: {lost['true_curb_labelled_road']:.2f})"
        in text
    )
    assert f"brings that to {lost_foot['true_curb_labelled_road']:.2f}" in text
    assert f"the curb IoU from {sfm['iou']['curb']:.2f} to {foot['iou']['curb']:.2f}" in text
    assert (
        f"spills onto {lost_foot['curb_label_on_true_road']:.2f} of true road cells instead of "
        f"{lost['curb_label_on_true_road']:.2f}"
    ) in text
    speed = {
        name: results(f"end_to_end_{name}.json")["annotator"]["speed_up"]
        for name in ("refine_on", "kerb_foot_width", "refine_on_9011", "kerb_foot_width_9011")
    }
    assert f"annotator goes from {speed['refine_on']:.2f}x to {speed['kerb_foot_width']:.2f}x" in text
    assert f"on 9011 from {speed['refine_on_9011']:.2f}x to {speed['kerb_foot_width_9011']:.2f}x" in text
    sfm_9011, foot_9011 = _surface_run(site_9011, "sfm"), site_9011["variant_kerb_foot"]
    assert f"{sfm_9011['iou']['curb']:.2f}" == f"{foot_9011['iou']['curb']:.2f}"
    assert f"curb IoU ({sfm_9011['iou']['curb']:.2f} either way)" in text
    lost_9011 = sfm_9011["curb_confusion"]
    assert (
        f"the curb label covers {lost_9011['curb_label_on_true_road']:.2f} of true road cells, "
        f"{lost_9011['true_curb_labelled_background']:.2f} of the true curb cells are labelled background, only "
        f"{lost_9011['true_curb_labelled_road']:.2f} road"
    ) in text


def test_element_mask_proposer_table() -> None:
    t = table("proposer", "bench/vma_masks.py")
    assert_names_source(t, "vma_masks.json", "bench/vma_masks.py")
    recorded = results("vma_masks.json")
    assert recorded["checkpoint"]["version"] in " ".join(t.rows)
    for label, key in (("rule-based", "rule_based"), ("element-mask network", "element_masks")):
        cells = row(t, next(name for name in t.rows if name.startswith(label)))
        for cell, condition in zip(cells[1:4], ("clean", "degraded", "reconstructed"), strict=True):
            figures = recorded["results"][condition][key]
            scored = figures["observed_truth"] if condition == "reconstructed" else figures
            assert_shows(cell, [scored["mean_ap"], figures["annotator"]["speed_up"]], f"{label} {condition}")
    margin = recorded["map_margin_over_rule_based"]
    text = " ".join(readme_text().split())
    assert f"(+{margin['reconstructed']:.3f}; +{margin['degraded']:.3f} on damaged)" in text


def test_element_mask_end_to_end_figures() -> None:
    text = " ".join(readme_text().split())
    masks, maptr = results("end_to_end_masks.json"), results("end_to_end_kerb_step.json")
    assert masks["proposer"] == "masks" and maptr["proposer"] == "learned"
    shown = (
        f"proposal mAP is {masks['proposals_ap']['observed_truth']['mean_ap']:.3f} against "
        f"{maptr['proposals_ap']['observed_truth']['mean_ap']:.2f} with the shipped MapTR-style model"
    )
    assert shown in text
    speed = f"speed-up {masks['annotator']['speed_up']:.2f}x against {maptr['annotator']['speed_up']:.2f}x"
    assert speed in text
    counts = masks["annotator"]["corrected"]["counts"]
    assert f"it accepts {counts['accept']} proposals" in text and f"draws {counts['drawn']} instead" in text
    v3 = results("end_to_end_masks_v0003.json")
    v3_counts = v3["annotator"]["corrected"]["counts"]
    shown_v3 = (
        f"proposal mAP is {v3['proposals_ap']['observed_truth']['mean_ap']:.3f} and the speed-up "
        f"{v3['annotator']['speed_up']:.2f}x against v0002's {masks['annotator']['speed_up']:.2f}x: "
        f"{v3_counts['accept']} accepted, {v3_counts['fix']} fixed, {v3_counts['reject']} rejected, "
        f"{v3_counts['drawn']} drawn (v0002: {counts['accept']}, {counts['fix']}, {counts['reject']}, "
        f"{counts['drawn']})"
    )
    assert shown_v3 in text
    today = {v: results(f"end_to_end_masks_{v}.json") for v in ("v0004", "v0003_today")}
    for version, recorded in today.items():
        assert recorded["proposed_by"] == [f"vma-masks-{version.split('_')[0]}"]
    (v4, v3_today) = (
        (
            f"{r['proposals_ap']['observed_truth']['mean_ap']:.3f} and",
            f"{r['annotator']['speed_up']:.2f}x",
            r["annotator"]["corrected"]["counts"],
        )
        for r in today.values()
    )
    assert f"v0004 gives proposal mAP {v4[0]} the speed-up {v4[1]}" in text
    assert (
        f"{v4[2]['accept']} accepted, {v4[2]['fix']} fixed, {v4[2]['reject']} rejected, {v4[2]['drawn']} drawn"
        in text
    )
    assert f"and v0003 {v3_today[0]} {v3_today[1]}" in text
    c = v3_today[2]
    assert (
        f"end_to_end_masks_v0003_today.json`: {c['accept']}, {c['fix']}, {c['reject']}, {c['drawn']};" in text
    )


def _reconstructed_figures(figures: dict[str, Any]) -> list[Expected]:
    recon = figures["reconstructed"]
    return [recon["observed_truth"]["mean_ap"], recon["annotator"]["speed_up"]]


def _check_mask_loop_table(first_column: str, results_file: str, *, reconstructed: bool) -> dict[str, Any]:
    """A table of the element-mask loop's rounds against its results: each round's promoted version, its
    kept-out candidate, retrain seconds, held-out figures (and, with `reconstructed`, the reconstructed-raster
    figures in the next column), and the rule-based row."""
    t = table(first_column)
    assert_names_source(t, results_file, "bench/vma_loop.py")
    recorded = results(results_file)
    for entry in recorded["rounds"]:
        label = f"{first_column} {entry['round']}"
        cells = row(t, next(name for name in t.rows if name.split(" ")[0] == str(entry["round"])))
        assert entry["heldout"]["version"] in cells[1]
        if "candidate" in entry:
            assert entry["candidate"] in cells[1] and ("kept out" in cells[1]) != entry["promoted"]
            assert_shows(cells[2], [entry["retrain_seconds"]], f"{label} seconds")
        assert_shows(cells[3], _loop_figures(entry["heldout"]), label)
        if reconstructed:
            assert_shows(cells[4], _reconstructed_figures(entry["heldout"]), f"{label} reconstructed")
    rule = row(t, "rule-based")
    assert_shows(rule[3], _loop_figures(recorded["rule_based"]), "rule-based")
    if reconstructed:
        assert_shows(rule[4], _reconstructed_figures(recorded["rule_based"]), "rule-based reconstructed")
    return recorded


def test_element_mask_loop_rounds_table() -> None:
    recorded = _check_mask_loop_table("masks round", "vma_loop_masks.json", reconstructed=True)
    last = recorded["rounds"][-1]["heldout"]["reconstructed"]["observed_truth"]["mean_ap"]
    rule = recorded["rule_based"]["reconstructed"]["observed_truth"]["mean_ap"]
    text = " ".join(readme_text().split())
    assert f"nor after the loop ({recorded['rounds'][-1]['heldout']['version']}: +{last - rule:.3f})" in text


def test_element_mask_loop_from_a_first_model_table() -> None:
    recorded = _check_mask_loop_table(
        "first-model round", "vma_loop_masks_bootstrap.json", reconstructed=True
    )
    assert "--bootstrap-seeds" in recorded["command"]


REHEARSAL_RUNS = {
    "none, 4000-4002": "vma_loop_masks_no_replay.json",
    "4 sites at 0.5, 4000-4002": "vma_loop_masks_replay.json",
    "none, 4003-4005": "vma_loop_masks_4003_replay0.json",
    "4 sites at 0.5, 4003-4005": "vma_loop_masks_4003_replay4.json",
}


def _gate_figures(gate: dict[str, Any]) -> list[Expected]:
    """What a loop round's gate said: the candidate's validation mAP and correction seconds, then the current's."""
    return [
        gate["candidate"]["mean_ap"],
        gate["candidate"]["review"]["correction_s"],
        gate["current"]["mean_ap"],
        gate["current"]["review"]["correction_s"],
    ]


def test_loop_with_and_without_rehearsal_table() -> None:
    """Each run's promoted version after rounds 1-3, its round-2 candidate's gate figures (validation mAP and
    correction seconds, candidate then current), and the held-out and reconstructed figures after round 3."""
    t = table("rehearsal, new sites")
    for label, results_file in REHEARSAL_RUNS.items():
        assert_names_source(t, results_file, "bench/vma_loop.py")
        recorded = results(results_file)
        replay_sites = 0 if label.startswith("none") else 4
        assert f"--replay-sites {replay_sites} --replay-share 0.5" in recorded["command"]
        assert f"--new-seeds {label.split(', ')[1]}" in recorded["command"]
        cells = row(t, label)
        rounds = recorded["rounds"]
        assert cells[1].split(" / ") == [r["heldout"]["version"] for r in rounds[1:]], label
        assert_shows(cells[2], _gate_figures(rounds[2]["gate"]), f"{label} round-2 gate")
        assert_shows(cells[3], _loop_figures(rounds[-1]["heldout"]), f"{label} held-out")
        assert_shows(cells[4], _reconstructed_figures(rounds[-1]["heldout"]), f"{label} reconstructed")


VMA_APPEARANCE_SITES = {
    "default": "data/synthetic/default",
    "9001": "data/synthetic/random-9001",
    "9007 (looked at to find the cause)": "data/synthetic/random-9007",
    "9011 (fresh)": "data/synthetic/random-9011",
}


def _check_per_site_columns(
    t: MarkdownTable,
    by_version: dict[str, dict[str, Any]],
    columns: dict[str, tuple[str, str]],
    site_rows: dict[str, str],
    bev_speed: bool = False,
    all_row: str = "all four: mAP, speed-up",
) -> None:
    """Each column (header -> (version, proposer)) of a per-site table of bench/vma_masks.py runs: mAP per
    reconstructed site, over all of them with the annotator's speed-up, and on the BEV sites (with their
    speed-ups when `bev_speed`)."""
    for header, (version, proposer) in columns.items():
        index = t.header.index(header)
        figures_of = by_version[version]["results"]
        recon = figures_of["reconstructed"][proposer]
        for label, site in site_rows.items():
            expected = [recon["observed_truth"]["per_site"][site]["mean_ap"]]
            assert_shows(row(t, label)[index], expected, f"{header} {label}")
        assert_shows(
            row(t, all_row)[index],
            [recon["observed_truth"]["mean_ap"], recon["annotator"]["speed_up"]],
            f"{header} {all_row}",
        )
        bev: list[Expected] = [
            figures_of["clean"][proposer]["mean_ap"],
            figures_of["degraded"][proposer]["mean_ap"],
        ]
        if bev_speed:
            bev += [
                figures_of["clean"][proposer]["annotator"]["speed_up"],
                figures_of["degraded"][proposer]["annotator"]["speed_up"],
            ]
        label = next(name for name in t.rows if name.startswith("BEV 5000-5004"))
        assert_shows(row(t, label)[index], bev, f"{header} BEV")


def test_element_mask_appearance_table_per_site() -> None:
    t = table("reconstructed site", "jitter_appearance")
    assert_names_source(t, "vma_masks_v0003.json", "bench/vma_masks.py")
    assert "bench/results/vma_masks_v0002_sites.json" in t.context
    by_version = {"v0002": results("vma_masks_v0002_sites.json"), "v0003": results("vma_masks_v0003.json")}
    assert {v: r["checkpoint"]["version"] for v, r in by_version.items()} == {
        "v0002": "v0002",
        "v0003": "v0003",
    }
    columns = {"rule-based": ("v0003", "rule_based"), "v0002": ("v0002", "element_masks")}
    columns["v0003"] = ("v0003", "element_masks")
    _check_per_site_columns(t, by_version, columns, VMA_APPEARANCE_SITES)
    rules_then = by_version["v0002"]["results"]["reconstructed"]["rule_based"]["observed_truth"]["mean_ap"]
    assert (
        rules_then
        == by_version["v0003"]["results"]["reconstructed"]["rule_based"]["observed_truth"]["mean_ap"]
    )


def test_kept_loop_round_is_the_loops_round_one() -> None:
    """The v0004 confirmed below was kept from a rerun of round 1, which must have measured what the loop did."""
    kept, loop = results("vma_loop_masks_round1_kept.json"), results("vma_loop_masks.json")
    assert kept["rounds"][1]["heldout"] == loop["rounds"][1]["heldout"]
    assert "bench/results/vma_loop_masks_round1_kept.json" in " ".join(readme_text().split())


def test_loop_candidate_confirmation_table() -> None:
    t = table("loop candidate, confirmed", "bench/vma_masks.py")
    assert_names_source(t, "vma_masks_confirm_v0004.json", "bench/vma_masks.py")
    assert "bench/results/vma_masks_confirm_v0003_today.json" in t.context
    by_version = {
        "v0003": results("vma_masks_confirm_v0003_today.json"),
        "v0004": results("vma_masks_confirm_v0004.json"),
    }
    assert {v: r["checkpoint"]["version"] for v, r in by_version.items()} == {
        "v0003": "v0003",
        "v0004": "v0004",
    }
    columns = {
        "rule-based": ("v0003", "rule_based"),
        "v0003 (shipped)": ("v0003", "element_masks"),
        "v0004 (loop round 1)": ("v0004", "element_masks"),
    }
    sites = {label.split(" ")[0]: site for label, site in VMA_APPEARANCE_SITES.items()}
    _check_per_site_columns(t, by_version, columns, sites, bev_speed=True)
    recon = {
        v: r["results"]["reconstructed"]["element_masks"]["observed_truth"]["mean_ap"]
        for v, r in by_version.items()
    }
    margin = {v: r["map_margin_over_rule_based"]["reconstructed"] for v, r in by_version.items()}
    text = " ".join(readme_text().split())
    assert (
        f"+{recon['v0004'] - recon['v0003']:.3f} mAP over the four (+{margin['v0004']:.3f} over the rules, the "
        f"issue's 0.05 met there; v0003 +{margin['v0003']:.3f})"
    ) in text


SEGMENT_CALIBRATION_COLUMNS = {
    "9001 shipped-v2": ("segment_v2_rerun_9001.json", "shipped-v2"),
    "9001 calibrated": ("segment_v3_9001.json", "shipped-v3"),
    "9002 shipped-v2": ("segment_v2_rerun_9002.json", "shipped-v2"),
    "9002 calibrated": ("segment_v3_9002.json", "shipped-v3"),
}


def _check_segmenter_columns(title: str, columns: dict[str, tuple[str, str]]) -> None:
    """Each column of a README segmenter table shows its results file's per-class IoU (rows named by class) and,
    in a row starting "whole path", the predicted-minus-generator-masks differences ("not run" for a file made
    with --skip-pipeline); the checkpoint label fits."""
    t = table(title)
    for column, (name, label) in columns.items():
        assert_names_source(t, name, "bench/segment.py")
        index = t.header.index(column)
        recorded = results(name)
        assert recorded["segmentation"]["checkpoint"]["label"] == label
        for row_label, cells in t.rows.items():
            if row_label.startswith("whole path") and "differences" not in recorded:
                assert cells[index] == "not run", f"{title}: {column} has no whole-path run"
                continue
            if row_label.startswith("whole path"):
                differences = recorded["differences"]
                expected = [
                    differences[key]["predicted_minus_reference"]
                    for key in ("proposal_map", "elevation_rmse_cm", "sre_ref_px")
                ]
            else:
                expected = [recorded["segmentation"]["per_class_iou"][row_label.replace(" ", "_")]]
            assert_shows(cells[index], expected, f"{title}: {column} {row_label!r}")


def test_segmenter_calibration_table() -> None:
    _check_segmenter_columns("class, calibration", SEGMENT_CALIBRATION_COLUMNS)


SEGMENT_REFINEMENT_COLUMNS = {
    f"{site} {label}": (f"segment_refine_{short}_{site}.json", label)
    for site, versions in (("9001", "v2 cap2 cap1"), ("9002", "v2 cap2 cap1"), ("9004", "v2 cap2"))
    for short in versions.split()
    for label in ["shipped-v2" if short == "v2" else f"refined-{short}"]
}


def test_segmenter_refinement_table() -> None:
    _check_segmenter_columns("class, full-resolution refinement", SEGMENT_REFINEMENT_COLUMNS)


def test_segmenter_refinement_default_size_table() -> None:
    """Site 9003 scored against the warped masks its ground truth first held and against the exact ones."""
    columns = {
        f"9003 {label}{truth}": (f"segment_{kind}_{short}_9003.json", label)
        for short, label in (("v2", "shipped-v2"), ("cap2", "refined-cap2"))
        for kind, truth in (("refine", ", warped truth"), ("exact", ""))
    }
    _check_segmenter_columns("class, default-size site 9003", columns)
    text = " ".join(readme_text().split())
    vehicle = [
        results(f"segment_exact_{v}_9003.json")["segmentation"]["per_class_iou"]["vehicle"]
        for v in ("v2", "cap2")
    ]
    assert f"vehicle meets its target ({vehicle[0]:.3f} -> {vehicle[1]:.3f})" in text and vehicle[1] >= 0.8
    exact = results("segment_exact_cap2_9003.json")["segmentation"]
    assert exact["site"]["seed"] == 9003 and exact["edge_errors"]["lane_marking"]["union_pixels"] > 0


def test_segmenter_refinement_ceiling_speed_and_shipped_checkpoint() -> None:
    """The stride-2 ceilings quoted are the files', the speeds are the speed bench's, refined-cap2 is the
    checkpoint measured under that name and the parent of the shipped one, whose speed is quoted beside it."""
    text = " ".join(readme_text().split())
    ceilings = {
        site: results(f"segment_refine_cap2_{site}.json")["segmentation"]["resolution_ceiling_iou"][
            "stride_2"
        ]
        for site in ("9001", "9002", "9004")
    }
    lane = {site: f"{c['lane_marking']:.2f}" for site, c in ceilings.items()}
    curb = {site: f"{c['curb']:.2f}" for site, c in ceilings.items()}
    assert (
        f"give lane marking an IoU of {lane['9001']} and curb {curb['9001']} on site 9001, {lane['9002']} / "
        f"{curb['9002']} on 9002 and {lane['9004']} / {curb['9004']} on 9004"
    ) in text
    speed = results("segment_speed.json")
    assert speed["baseline"] == "shipped-v2"
    ours, baseline = speed["checkpoints"]["refined-cap2"], speed["checkpoints"]["shipped-v2"]
    assert (
        f"It costs {ours['seconds_per_512x288_image']:.3f} s per 512x288 image on one CPU thread against "
        f"`shipped-v2`'s {baseline['seconds_per_512x288_image']:.3f} s, {ours['ratio_to_baseline']:.2f}x"
    ) in text
    measured = results("segment_refine_cap2_9004.json")["segmentation"]["checkpoint"]
    assert measured["label"] == "refined-cap2" and measured["digest"] == ours["digest"]
    successor = speed["checkpoints"]["refined-scale1"]
    assert successor["digest"] == _gpu_run("gpu-long")["parent"]["weights_sha256"][:16]
    assert (
        f"and so is its cost: {successor['seconds_per_512x288_image']:.3f} s per 512x288 image on one thread "
        f"against {ours['seconds_per_512x288_image']:.3f} s"
    ) in text


SEGMENT_OWN_SCALE_COLUMNS = {
    f"{site} {label}": (f"segment_{kind}_{short}_{site}.json", label)
    for site, kinds in (
        ("9001", ("refine", "sites")),
        ("9002", ("refine", "sites")),
        ("9004", ("refine", "sites")),
        ("9005", ("sites", "sites")),
        ("9003", ("exact", "exact")),
    )
    for (short, label), kind in zip(
        (("cap2", "refined-cap2"), ("scale1", "refined-scale1")), kinds, strict=True
    )
}


def test_segmenter_own_scale_tables_and_shipped_checkpoint() -> None:
    """The rescale A/B and the shipped refined-scale1 on every measurement site; the shipped checkpoint is the
    one measured, trained without the rescale, and the rescaled control differs from it only there."""
    _check_segmenter_columns(
        "class, rescaled or not",
        {
            f"{site} {label}": (f"segment_sites_{short}_{site}.json", label)
            for site in ("9001", "9005")
            for short, label in (("rescaled", "more-sites"), ("scale1", "refined-scale1"))
        },
    )
    _check_segmenter_columns("class, images at their own scale", SEGMENT_OWN_SCALE_COLUMNS)
    scale1 = _gpu_run("gpu-long")["parent"]  # the checkpoint the GPU runs went on from
    assert scale1["label"] == "refined-scale1"
    for name in SEGMENT_OWN_SCALE_COLUMNS.values():
        measured = results(name[0])["segmentation"]["checkpoint"]
        if measured["label"] == "refined-scale1":
            assert measured["digest"] == scale1["weights_sha256"][:16]
    control = results("segment_sites_rescaled_9001.json")["segmentation"]
    ours = results("segment_sites_scale1_9001.json")["segmentation"]
    lane_edges = [
        run["edge_errors"]["lane_marking"]["missed_on_edge"]
        + run["edge_errors"]["lane_marking"]["extra_on_edge"]
        for run in (control, ours)
    ]
    text = " ".join(readme_text().split())
    assert (
        f"the lane-marking edge error falls from {lane_edges[0] * 100:.0f} % to {lane_edges[1] * 100:.0f} % of the union"
        in text
    )
    assert lane_edges[1] < lane_edges[0]


SEGMENT_MORE_SITES_COLUMNS = {
    f"{site} {label}": (f"segment_sites_{short}_{site}.json", label)
    for site in ("9002", "9004", "9005", "9006")
    for short, label in (("scale1", "refined-scale1"), ("more", "scale1-more"), ("fade", "scale1-fade"))
}


def test_segmenter_more_sites_and_paint_fade_table() -> None:
    """The paint-fade A/B and the 38-site continuation on four sites; the README's reading of it (the fade lowers
    road everywhere; more sites raise lane marking everywhere) holds, and the shipped checkpoint stayed."""
    _check_segmenter_columns("class, more sites and paint fade", SEGMENT_MORE_SITES_COLUMNS)
    for site in ("9002", "9004", "9005", "9006"):
        iou = {
            short: results(f"segment_sites_{short}_{site}.json")["segmentation"]["per_class_iou"]
            for short in ("scale1", "more", "fade")
        }
        assert iou["fade"]["road"] < iou["more"]["road"], site
        assert iou["more"]["lane_marking"] > iou["scale1"]["lane_marking"], site


def _gpu_run(label: str) -> dict[str, Any]:
    """The report of the lent-GPU run that made segmenter checkpoint `label`."""
    (run,) = [run for run in results("segmenter_gpu_runs.json")["runs"] if run["label"] == label]
    return run


SEGMENT_GPU_COLUMNS = {
    **{
        f"{site} {label}": (name, label)
        for site in ("9002", "9004", "9005", "9006")
        for name, label in (
            (f"segment_sites_scale1_{site}.json", "refined-scale1"),
            (f"segment_gpu_path_{site}.json", "gpu-long2"),
        )
    },
    "9003 refined-scale1": ("segment_exact_scale1_9003.json", "refined-scale1"),
    "9003 gpu-long2": ("segment_gpu_path_9003.json", "gpu-long2"),
}


def test_segmenter_trained_on_a_gpu_table_and_shipped_checkpoint() -> None:
    """The GPU-trained checkpoint beside refined-scale1 on five measurement sites; it is the one shipped, its
    lineage is the recorded runs', README's reading of the table (better everywhere, the whole path within its
    tolerances on every tiny site) holds, and the runs' figures are their results file's."""
    _check_segmenter_columns("class, trained on a GPU", SEGMENT_GPU_COLUMNS)
    shipped = json.loads((ROOT / "cama_pipeline/segment/shipped/checkpoint.json").read_text(encoding="utf-8"))
    first, second = _gpu_run("gpu-long"), _gpu_run("gpu-long2")
    assert shipped["label"] == "gpu-long2" and shipped["weights_sha256"] == second["weights_sha256"]
    assert second["parent"]["weights_sha256"] == first["weights_sha256"]
    assert first["parent"]["label"] == "refined-scale1"
    digests = {
        "gpu-long2": second["weights_sha256"][:16],
        "refined-scale1": first["parent"]["weights_sha256"][:16],
    }
    for name, label in SEGMENT_GPU_COLUMNS.values():
        assert results(name)["segmentation"]["checkpoint"]["digest"] == digests[label], name
    for site in ("9002", "9004", "9005", "9006", "9003"):
        before = results(SEGMENT_GPU_COLUMNS[f"{site} refined-scale1"][0])["segmentation"]["per_class_iou"]
        after = results(SEGMENT_GPU_COLUMNS[f"{site} gpu-long2"][0])["segmentation"]["per_class_iou"]
        for cls in ("road", "lane_marking", "crosswalk", "curb", "vehicle", "ego"):
            assert after[cls] > before[cls], (site, cls)
    for site in ("9002", "9004", "9005", "9006", "9003"):
        differences = results(f"segment_gpu_path_{site}.json")["differences"]
        assert all(differences[key]["met"] for key in ("proposal_map", "elevation_rmse_cm", "sre_ref_px")), (
            site
        )
    text = " ".join(readme_text().split())
    runs = results("segment_gpu_path_9003.json")["runs"]
    bev = [
        f"{runs[kind]['bev_iou'][cls]:.3f}"
        for cls in ("road", "lane_marking", "crosswalk", "curb")
        for kind in ("predicted_masks", "generator_masks")
    ]
    assert (
        f"road ({bev[0]} against {bev[1]}) and lane marking ({bev[2]} against {bev[3]}), under it for crosswalk "
        f"({bev[4]} against {bev[5]}) and above it for curb ({bev[6]} against {bev[7]};"
    ) in text
    for site in ("9004", "9005", "9006", "9003"):
        speed_up = results(f"segment_gpu_path_{site}.json")["differences"]["annotator_speed_up"]
        shown = f"{speed_up['reference']:.2f}x -> {speed_up['predicted']:.2f}x"
        assert f"{site} {shown}" in text or f"on {site} ({shown})" in text, (site, shown)
    assert (
        f"the sites took {first['sites_seconds']:.0f} s on {first['cpu_count']} cores, the training "
        f"{first['train']['time_budget_s']:.0f} s, {first['steps']:,} steps ({first['passes']:.1f} passes, "
        f"{first['crops_per_second']:.0f} crops a second)"
    ) in text
    assert (
        f"at a peak of 5e-4 for {second['train']['time_budget_s']:.0f} s ({second['steps']:,} steps, "
        f"{second['passes']:.1f} passes)"
    ) in text
    crops = (first["steps"] + second["steps"]) * first["train"]["batch_size"]
    assert f"That is {round(crops, -3):,.0f} crops of 288x512" in text
    assert second["train"]["batch_size"] == first["train"]["batch_size"]
    held = [
        f"{name.replace('_', ' ')} {first['held_out'][name]:.3f} -> {second['held_out'][name]:.3f}"
        for name in ("lane_marking", "curb", "crosswalk")
    ]
    assert f"(network-level IoU: {', '.join(held)})" in text
    assert first["device"] == second["device"] == "NVIDIA H200"


def test_segmenter_mirror_averaging_table() -> None:
    """Mirror averaging beside the plain GPU-trained checkpoint on the same five sites, the whole path too; the
    README's reading (every class but ego better, the tolerances kept) and the cost hold."""
    sites = ("9002", "9004", "9005", "9006", "9003")
    _check_segmenter_columns(
        "class, mirror averaging",
        {
            f"{site} {column}": (name, "gpu-long2")
            for site in sites
            for column, name in (
                ("gpu-long2", f"segment_gpu_path_{site}.json"),
                ("mirrored", f"segment_gpu_flip_path_{site}.json"),
            )
        },
    )
    text = " ".join(readme_text().split())
    for site in sites:
        plain = results(f"segment_gpu_path_{site}.json")
        mirrored = results(f"segment_gpu_flip_path_{site}.json")
        assert mirrored["segmentation"]["flip_average"] is True and "--flip-average" in mirrored["command"]
        assert "flip_average" not in plain["segmentation"] and "--flip-average" not in plain["command"]
        before, after = plain["segmentation"]["per_class_iou"], mirrored["segmentation"]["per_class_iou"]
        for cls in ("road", "lane_marking", "crosswalk", "curb", "vehicle"):
            assert after[cls] > before[cls], (site, cls)
        differences = mirrored["differences"]
        assert all(differences[key]["met"] for key in ("proposal_map", "elevation_rmse_cm", "sre_ref_px")), (
            site
        )
        speed_ups = [run["differences"]["annotator_speed_up"]["predicted"] for run in (plain, mirrored)]
        assert f"{site} {speed_ups[0]:.2f}x -> {speed_ups[1]:.2f}x" in text
    speed = results("segment_speed_flip.json")["checkpoints"]["gpu-long2"]
    assert not speed["flip_average_target_met"] and speed["target_met"]
    assert (
        f"{speed['flip_average_seconds']:.3f} s per 512x288 image on one thread against "
        f"{speed['seconds_per_512x288_image']:.3f} s plain, {speed['flip_average_ratio_to_plain']:.2f}x"
    ) in text


def test_segmenter_calibrated_scale1_table() -> None:
    _check_segmenter_columns(
        "class, refined-scale1 calibrated",
        {
            f"{site} scale1-cal": (f"segment_sites_cal_{site}.json", "scale1-cal")
            for site in ("9002", "9004", "9005", "9006")
        },
    )


def test_segmenter_rescale_with_resampled_shares_table() -> None:
    _check_segmenter_columns(
        "class, rescale with resampled shares",
        {
            f"{site} scale1-rescale": (f"segment_sites_rescale_{site}.json", "scale1-rescale")
            for site in ("9002", "9004", "9005", "9006")
        },
    )


def test_refinement_end_to_end_table() -> None:
    t = table("end to end, site and refinement", "bench/end_to_end.py")
    for site, suffix in (("default", ""), ("9011", "_9011")):
        for state in ("off", "on"):
            name = f"end_to_end_refine_{state}{suffix}.json"
            assert name in t.context
            recorded = results(name)
            assert recorded["proposer"] == "masks"
            ap, annotator = recorded["proposals_ap"]["observed_truth"], recorded["annotator"]
            counts = annotator["corrected"]["counts"]
            expected: list[Expected] = [ap["mean_ap"], ap["class_ap"]["divider"], annotator["speed_up"]]
            expected += [counts["accept"], counts["fix"], counts["reject"], counts["drawn"]]
            expected += [recorded["elevation"]["rmse_cm"], recorded["sre"]["c1_proposals"]["sre_ref_px"]]
            assert_shows(" | ".join(row(t, f"{site}, {state}")[1:]), expected, f"refinement {site} {state}")


GATE_RUNS = {
    "BEV sites 3000-3002": ("vma_loop_masks_no_replay.json", "--val-seeds 3000-3002 "),
    "reconstructions of 9007, 9011": (
        "vma_loop_masks_recon_gate.json",
        "--val-seeds '' --heldout-seeds 2000-2004 --recon-site data/synthetic/default --recon-site "
        "data/synthetic/random-9001 --gate-recon-site data/synthetic/random-9007 --gate-recon-site "
        "data/synthetic/random-9011 --replay-sites 0",
    ),
    "both: BEV sites 3000-3002 and reconstructions of 9007, 9011": (
        "vma_loop_masks_mixed_gate.json",
        "--val-seeds '3000-3002' --heldout-seeds 2000-2004 --recon-site data/synthetic/default --recon-site "
        "data/synthetic/random-9001 --gate-recon-site data/synthetic/random-9007 --gate-recon-site "
        "data/synthetic/random-9011 --replay-sites 0",
    ),
}


def test_loop_gated_on_bev_sites_or_reconstructions_table() -> None:
    """Each gate's promoted version after rounds 1-3, what its gate said of round 1's candidate, and the
    held-out BEV figures after round 3."""
    t = table("gate's validation sites")
    for label, (results_file, options) in GATE_RUNS.items():
        assert_names_source(t, results_file, "bench/vma_loop.py")
        recorded = results(results_file)
        assert options in recorded["command"] and "--new-seeds 4000-4002" in recorded["command"], label
        cells = row(t, label)
        rounds = recorded["rounds"]
        assert cells[1].split(" / ") == [r["heldout"]["version"] for r in rounds[1:]], label
        assert rounds[1]["candidate"] == "v0004"
        assert_shows(cells[2], _gate_figures(rounds[1]["gate"]), f"{label} round-1 gate")
        assert_shows(cells[3], _loop_figures(rounds[-1]["heldout"]), f"{label} held-out")
    gated = results("vma_loop_masks_recon_gate.json")["rounds"][1]["gate"]["current"]["sites"]
    assert all("(reconstructed: " in site for site in gated), gated
    both = results("vma_loop_masks_mixed_gate.json")["rounds"][1]["gate"]["current"]["sites"]
    assert sum("(reconstructed: " in site for site in both) == 2 and len(both) == 5, both


GATE_CONFIRM_SITES = {
    "default": "data/synthetic/default",
    **{seed: f"data/synthetic/random-{seed}" for seed in ("9001", "9013", "9017", "9019")},
}


def _confirmation_runs(t: MarkdownTable, files: dict[str, str]) -> dict[str, dict[str, Any]]:
    """The bench/vma_masks.py runs (key -> results file) a confirmation table names, each on BEV sites 5000-5004."""
    runs = {key: results(name) for key, name in files.items()}
    for key, name in files.items():
        assert_names_source(t, name, "bench/vma_masks.py")
        assert "--seeds 5000-5004" in runs[key]["command"], key
    return runs


def test_gate_choice_confirmation_table() -> None:
    t = table("gate's choice, confirmed", "bench/vma_masks.py")
    by_version = _confirmation_runs(
        t, {v: f"vma_masks_gate_confirm_{v}.json" for v in ("v0003", "v0004", "v0006")}
    )
    for version, recorded in by_version.items():
        assert recorded["checkpoint"]["version"] == version
    columns = {
        "rule-based": ("v0003", "rule_based"),
        "v0003 (shipped)": ("v0003", "element_masks"),
        "v0004 (BEV gate)": ("v0004", "element_masks"),
        "v0006 (reconstruction gate)": ("v0006", "element_masks"),
    }
    _check_per_site_columns(
        t, by_version, columns, GATE_CONFIRM_SITES, bev_speed=True, all_row="all five: mAP, speed-up"
    )


RECON_TRAINED_SITES = {
    "default": "data/synthetic/default",
    **{seed: f"data/synthetic/random-{seed}" for seed in ("9001", "9013", "9017", "9019", "9021")},
}


def test_training_on_reconstructions_confirmation_table() -> None:
    t = table("trained on reconstructions, confirmed", "bench/vma_masks.py")
    files = {
        "v0003": "vma_masks_recon_trained_confirm_v0003.json",
        "bev only": "vma_masks_recon_trained_confirm_bev_only.json",
        "reconstructions": "vma_masks_recon_trained_confirm.json",
    }
    by_version = _confirmation_runs(t, files)
    assert by_version["v0003"]["checkpoint"]["version"] == "v0003"
    assert by_version["bev only"]["checkpoint"]["data"]["reconstructions"] == []
    assert len(by_version["reconstructions"]["checkpoint"]["data"]["reconstructions"]) == 12
    shipped = ROOT / "models" / "vma" / "element_masks" / "checkpoints"
    assert json.loads((shipped / "current.json").read_text())["version"] == "v0004"
    shipped_data = json.loads((shipped / "v0004" / "checkpoint.json").read_text())["data"]
    assert by_version["reconstructions"]["checkpoint"]["data"] == shipped_data  # the measured one is shipped
    columns = {
        "rule-based": ("v0003", "rule_based"),
        "v0003": ("v0003", "element_masks"),
        "BEV only, 1,200 more steps": ("bev only", "element_masks"),
        "BEV and 12 reconstructions, 1,200 more steps (v0004, shipped)": ("reconstructions", "element_masks"),
    }
    _check_per_site_columns(
        t, by_version, columns, RECON_TRAINED_SITES, bev_speed=True, all_row="all six: mAP, speed-up"
    )


def test_training_on_reconstructions_at_the_gates_sites() -> None:
    text = " ".join(readme_text().split())
    ours, v0003 = (
        results(f"vma_masks_recon_trained_validation{suffix}.json")["results"] for suffix in ("", "_v0003")
    )

    def shown(figures: dict[str, Any], condition: str, key: str) -> str:
        scored = figures[condition]["element_masks"]
        if key == "speed_up":
            return f"{scored['annotator']['speed_up']:.2f}x"
        return f"{(scored['observed_truth'] if condition == 'reconstructed' else scored)['mean_ap']:.3f}"

    expected = (
        f"reconstructions {shown(ours, 'reconstructed', 'map')} against {shown(v0003, 'reconstructed', 'map')}, "
        f"{shown(ours, 'reconstructed', 'speed_up')} against {shown(v0003, 'reconstructed', 'speed_up')}; "
        f"BEV {shown(ours, 'clean', 'map')} against {shown(v0003, 'clean', 'map')}, "
        f"{shown(ours, 'clean', 'speed_up')} against {shown(v0003, 'clean', 'speed_up')}"
    )
    assert expected in text


def test_loop_on_reconstructions_table() -> None:
    """Each round's promoted version, retrain seconds, what the gate said and the held-out figures after it."""
    t = table("round on reconstructions", "bench/vma_loop.py")
    assert_names_source(t, "vma_loop_masks_recon_rounds.json", "bench/vma_loop.py")
    recorded = results("vma_loop_masks_recon_rounds.json")
    assert "--new-recon-site data/synthetic/random-9113" in recorded["command"]
    _check_rounds(t, recorded, recon_column=5, bev_column=4)


def _check_rounds(
    t: MarkdownTable, recorded: dict[str, Any], recon_column: int, bev_column: int | None
) -> None:
    """Each round's row of a loop table on reconstructions: promoted version, retrain seconds and gate figures (the
    first four columns), the held-out BEV figures (`bev_column`, if shown) and the held-out reconstructions'."""
    for entry in recorded["rounds"]:
        label = next(name for name in t.rows if name.split(" ")[0] == str(entry["round"]))
        cells = row(t, label)
        assert cells[1].split(" ")[0] == entry["heldout"]["version"], label
        if entry["round"]:
            assert_shows(cells[2], [round(entry["retrain_seconds"])], f"{label} seconds")
            assert_shows(cells[3], _gate_figures(entry["gate"]), f"{label} gate")
            assert (entry["candidate"] + " kept out" in cells[1]) != entry["promoted"], label
        if bev_column is not None:
            assert_shows(cells[bev_column], _loop_figures(entry["heldout"]), f"{label} held-out")
        recon = entry["heldout"]["reconstructed"]
        assert_shows(
            cells[recon_column],
            [recon["observed_truth"]["mean_ap"], recon["annotator"]["speed_up"]],
            f"{label} recon",
        )


def test_more_reconstructions_not_shipped() -> None:
    text = " ".join(readme_text().split())
    candidate = results("vma_masks_recon_trained_validation_v0005.json")["results"]
    current = results("vma_masks_recon_trained_validation.json")["results"]

    def correction_s(figures: dict[str, Any]) -> float:
        return sum(
            figures[c]["element_masks"]["annotator"]["correction_s"] for c in ("clean", "reconstructed")
        )

    recon_map = [
        f["reconstructed"]["element_masks"]["observed_truth"]["mean_ap"] for f in (candidate, current)
    ]
    bev_map = [f["clean"]["element_masks"]["mean_ap"] for f in (candidate, current)]
    assert f"reconstructions ({recon_map[0]:.3f} against {recon_map[1]:.3f})" in text
    assert f"on BEV ({bev_map[0]:.3f} against {bev_map[1]:.3f})" in text
    assert f"both is {correction_s(candidate):.0f} s against {correction_s(current):.0f} s" in text
    assert correction_s(candidate) > correction_s(current)  # what keeps it out
    confirm = results("vma_masks_recon_trained_confirm_v0005.json")
    assert len(confirm["checkpoint"]["data"]["reconstructions"]) == 27
    shown = confirm["results"]["reconstructed"]["element_masks"]
    ours = results("vma_masks_recon_trained_confirm.json")["results"]["reconstructed"]["element_masks"]
    assert (
        f"it is {shown['observed_truth']['mean_ap']:.3f} and {shown['annotator']['speed_up']:.2f}x against v0004's "
        f"{ours['observed_truth']['mean_ap']:.3f} and {ours['annotator']['speed_up']:.2f}x"
    ) in text


def _recon_masks(record: dict[str, Any]) -> dict[str, Any]:
    """The element-mask network's figures on the reconstructions of a bench/vma_masks.py record."""
    return record["results"]["reconstructed"]["element_masks"]


def _site_class_ap(figures: dict[str, Any], site: str, cls: str) -> float:
    """One class's AP on the reconstruction whose path ends with `site`, in `_recon_masks` figures."""
    per_site = figures["observed_truth"]["per_site"]
    return float(next(v for k, v in per_site.items() if k.endswith(site))["class_ap"][cls])


def test_kerb_foot_with_the_shipped_network_table() -> None:
    """Each cell of the foot's table against its end-to-end and confirmation results, and the figures the
    paragraph below it quotes."""
    t = table("kerb foot and the network proposing", "bench/vma_masks.py")
    variants = {
        "off, v0004 (the defaults)": ("off_v0004", "off_v0004"),
        "on (`kerb_band_m = 0.3`), v0004": ("v0004", "v0004"),
        "on, v0004 trained on rasters with the foot": ("foot_trained", "foot_trained"),
        "off, v0004 trained on rasters with the foot": (None, "off_foot_trained"),
        "on, paint kept out of the foot and the foot labelled curb, v0004": ("curb_v0004", "curb_v0004"),
    }
    for label, (end_to_end, confirmation) in variants.items():
        cells = row(t, label)
        for index, site_suffix in ((1, ""), (2, "_9011")):
            if end_to_end is None:
                assert cells[index] == "not run", label
                continue
            name = f"end_to_end_kerb_foot_{end_to_end}{site_suffix}.json"
            assert_names_source(t, name, "bench/end_to_end.py")
            figures_of = results(name)
            expected = [
                figures_of["proposals_ap"]["observed_truth"]["mean_ap"],
                figures_of["annotator"]["speed_up"],
            ]
            assert_shows(cells[index], expected, f"{label} {name}")
        name = (
            "vma_masks_kerb_foot_curb_confirm_v0004.json"
            if confirmation == "curb_v0004"
            else f"vma_masks_kerb_foot_confirm_{confirmation}.json"
        )
        assert_names_source(t, name, "bench/vma_masks.py")
        confirm = results(name)
        trained_on_foot = any("/foot/" in path for path in confirm["checkpoint"]["data"]["reconstructions"])
        assert trained_on_foot == ("trained" in label), label
        # the rasters with the foot are the sites' copies; without it, the sites themselves
        assert ("--recon-site data/synthetic/default" in confirm["command"]) == label.startswith("off"), label
        scored = _recon_masks(confirm)
        assert_shows(cells[3], [scored["observed_truth"]["mean_ap"], scored["annotator"]["speed_up"]], label)
    off, on = (results(f"vma_masks_kerb_foot_confirm_{s}.json") for s in ("off_v0004", "v0004"))
    assert off["checkpoint"]["version"] == on["checkpoint"]["version"] == "v0004"
    shipped = _recon_masks(results("vma_masks_recon_trained_confirm.json"))
    baseline, with_foot = _recon_masks(off), _recon_masks(on)
    # the baseline repeats the v0004 column of the training table
    assert baseline["observed_truth"]["mean_ap"] == pytest.approx(shipped["observed_truth"]["mean_ap"])
    assert baseline["annotator"]["speed_up"] == pytest.approx(shipped["annotator"]["speed_up"])
    correction = [figures["annotator"]["correction_s"] for figures in (with_foot, baseline)]
    text = " ".join(readme_text().split())
    assert f"spends {correction[0]:.0f} s instead of {correction[1]:.0f} s" in text
    assert correction[0] > correction[1]  # what keeps the foot off
    trained = _recon_masks(results("vma_masks_kerb_foot_confirm_foot_trained.json"))
    assert (
        f"at {trained['observed_truth']['mean_ap']:.3f} mAP and {trained['annotator']['correction_s']:.0f} s of "
        "correction"
    ) in text
    assert trained["annotator"]["correction_s"] > correction[1]  # what keeps the network trained on it out
    boundary = [
        results(f"end_to_end_kerb_foot_{s}.json")["proposals_ap"]["observed_truth"]["class_ap"]["boundary"]
        for s in ("off_v0004", "v0004")
    ]
    assert f"boundary AP goes from {boundary[0]:.3f} to {boundary[1]:.3f}" in text
    for site, cls, where in (
        ("random-9001", "boundary", "boundary AP"),
        ("random-9021", "divider", "dividers"),
    ):
        ap = [_site_class_ap(figures, site, cls) for figures in (baseline, with_foot)]
        assert (
            f"{where} {ap[0]:.3f} -> {ap[1]:.3f}" in text or f"{where} ({ap[0]:.3f} -> {ap[1]:.3f})" in text
        )
    fixed = _recon_masks(results("vma_masks_kerb_foot_curb_confirm_v0004.json"))
    assert (
        f"correction time is {fixed['annotator']['correction_s']:.0f} s, against {correction[0]:.0f} s with the foot "
        f"as it was and {correction[1]:.0f} s without"
    ) in text
    assert fixed["annotator"]["correction_s"] > correction[1]  # what still keeps the changed foot off
    ap = [_site_class_ap(fixed, site, cls) for site, cls in (("9001", "boundary"), ("9021", "divider"))]
    assert f"9001's boundary AP {ap[0]:.3f}, 9021's divider AP {ap[1]:.3f}" in text
    before, after = (
        results(name)["variant_kerb_foot"] for name in ("surface.json", "surface_kerb_foot_paint_curb.json")
    )
    no_foot = results("surface_kerb_foot_paint_curb.json")["runs"][-1]
    assert (
        before["kerb_band_m"] == after["kerb_band_m"] == 0.3 and no_foot["poses"] == after["poses"] == "sfm"
    )
    assert (
        f"crosswalk IoU {no_foot['iou']['crosswalk']:.3f} without the foot, {before['iou']['crosswalk']:.3f} with it"
    ) in text
    assert (
        f"curb IoU is {after['iou']['curb']:.3f}, up from {before['iou']['curb']:.3f} in `bench/results/surface.json`, "
        f"crosswalk IoU is {after['iou']['crosswalk']:.3f}, as without the foot, and road IoU is {after['iou']['road']:.3f}"
    ) in text
    assert f"{after['iou']['crosswalk']:.3f}" == f"{no_foot['iou']['crosswalk']:.3f}"
    assert SurfaceConfig().kerb_step.kerb_band_m == 0.0  # the foot is off by default, as README says


def _annotator_cell(annotator: dict[str, Any]) -> list[Expected]:
    """Speed-up, then accepted / fixed / rejected / drawn, as the frame table shows an end-to-end run."""
    counts = annotator["corrected"]["counts"]
    return [annotator["speed_up"], *(counts.get(k, 0) for k in ("accept", "fix", "reject", "drawn"))]


def test_truth_in_the_reconstruction_frame_table() -> None:
    t = table("site and proposer", "bench/vma_masks.py")
    for results_file in (
        "end_to_end_frame_default.json",
        "end_to_end_frame_random-9011.json",
        "vma_masks_confirm_frame_v0004.json",
    ):
        assert_names_source(t, results_file, "bench/end_to_end.py")
    for label, name in (
        ("default, v0004, end to end", "default"),
        ("9011, v0004, end to end", "random-9011"),
    ):
        run = results(f"end_to_end_frame_{name}.json")
        frame = run["reconstruction_frame"]
        cells = row(t, label)
        assert_shows(cells[1], [frame["shift_cm"], -frame["scale_error_permille"]], label)
        assert frame["scale_error_permille"] < 0 and "short" in cells[1]
        assert_shows(cells[2], _annotator_cell(run["annotator"]), label)
        assert_shows(cells[3], _annotator_cell(run["annotator_in_reconstruction_frame"]), label)
    world = results("vma_masks_kerb_foot_confirm_off_v0004.json")
    framed = results("vma_masks_confirm_frame_v0004.json")
    assert world["command"] == framed["command"]  # the same sites, network and settings
    shifts = [f["shift_cm"] for f in framed["reconstruction_frames"].values()]
    scales = [f["scale_error_permille"] for f in framed["reconstruction_frames"].values()]
    cells = row(t, "six confirmation reconstructions, v0004")
    assert_shows(cells[1], [min(shifts), max(shifts), -min(scales), max(scales)], "six: frames")
    for label, proposer in (
        ("six confirmation reconstructions, v0004", "element_masks"),
        ("six confirmation reconstructions, rule-based", "rule_based"),
    ):
        cells = row(t, label)
        for cell, run in ((cells[2], world), (cells[3], framed)):
            figures = run["results"]["reconstructed"][proposer]
            assert_shows(
                cell, [figures["observed_truth"]["mean_ap"], figures["annotator"]["speed_up"]], label
            )
    margins = [run["map_margin_over_rule_based"]["reconstructed"] for run in (framed, world)]
    assert f"({margins[0]:.3f} mAP, {margins[1]:.3f} before)" in readme_text()


def test_surface_grid_ceiling_table() -> None:
    t = table("site", "bench/surface_grid.py")
    assert_names_source(t, "surface_grid.json", "bench/surface_grid.py")
    recorded = {Path(r["site"]).name: r["classes"] for r in results("surface_grid.json")["sites"]}
    for label, name in (
        ("default", "default"),
        ("9003 (default size, randomised)", "random-default-9003"),
        ("9001 (tiny)", "random-9001"),
        ("9011 (tiny)", "random-9011"),
    ):
        classes = [recorded[name][c] for c in ("curb", "lane_marking", "crosswalk")]
        cells = row(t, label)
        assert_shows(cells[1], [c["area_rule_iou"] for c in classes], label)
        assert_shows(cells[2], [c["undecided_per_true_cell"] for c in classes], label)


def test_segment_annotator_in_own_frame_table() -> None:
    t = table("site, frame shift", "bench/segment.py")
    for seed in ("9002", "9004", "9005", "9006"):
        assert_names_source(t, f"segment_frame_{seed}.json", "bench/segment.py")
        runs = results(f"segment_frame_{seed}.json")["runs"]
        reference, predicted = runs["generator_masks"], runs["predicted_masks"]
        label, cells = row_starting(t, f"{seed},")
        assert_shows(label, [int(seed), reference["reconstruction_frame"]["shift_cm"]], label)
        for cell, run in ((cells[1], reference), (cells[2], predicted)):
            assert_shows(
                cell, [run["annotator_speed_up"], run["annotator_speed_up_in_reconstruction_frame"]], label
            )
        maps = [run["proposals_ap"]["observed_truth"]["mean_ap"] for run in (reference, predicted)]
        assert_shows(cells[3], maps, label)
        assert all(
            d["met"] for d in results(f"segment_frame_{seed}.json")["differences"].values() if "met" in d
        )


def test_gate_comparisons_in_the_frame_table() -> None:
    t = table("reconstructions, proposer", "bench/vma_masks.py")
    for label, world_file, frame_file, proposer in (
        (
            "six confirmation sites, v0003",
            "vma_masks_recon_trained_confirm_v0003.json",
            "vma_masks_confirm_frame_v0003.json",
            "element_masks",
        ),
        (
            "six confirmation sites, v0004",
            "vma_masks_kerb_foot_confirm_off_v0004.json",
            "vma_masks_confirm_frame_v0004.json",
            "element_masks",
        ),
        (
            "validation 9007 and 9011, rule-based",
            "vma_masks_recon_trained_validation.json",
            "vma_masks_validation_frame_v0004.json",
            "rule_based",
        ),
        (
            "validation 9007 and 9011, v0003",
            "vma_masks_recon_trained_validation_v0003.json",
            "vma_masks_validation_frame_v0003.json",
            "element_masks",
        ),
        (
            "validation 9007 and 9011, v0004",
            "vma_masks_recon_trained_validation.json",
            "vma_masks_validation_frame_v0004.json",
            "element_masks",
        ),
    ):
        cells = row(t, label)
        world, framed = results(world_file), results(frame_file)
        assert (
            world["command"].split("--checkpoint")[1].split()[1:]
            == framed["command"].split("--checkpoint")[1].split()[1:]
        )
        for cell, run in ((cells[1], world), (cells[2], framed)):
            figures = run["results"]["reconstructed"][proposer]
            assert_shows(
                cell, [figures["observed_truth"]["mean_ap"], figures["annotator"]["speed_up"]], label
            )
        if proposer == "element_masks":
            assert label.endswith(framed["checkpoint"]["version"])


def test_training_towards_the_frame_table() -> None:
    """v0004's recipe with its reconstructions' targets in their frames, against v0004, on the gate's sites and
    the confirmation sites; the gate's correction seconds over both kinds."""
    t = table("network, where its training targets were", "bench/vma_masks.py")
    runs = {}
    for suffix in ("v0004", "trained"):
        for kind in ("validation", "confirm"):
            assert_names_source(t, f"vma_masks_{kind}_frame_{suffix}.json", "bench/vma_masks.py")
            runs[kind, suffix] = results(f"vma_masks_{kind}_frame_{suffix}.json")
    for label, suffix in (
        ("v0004, the world", "v0004"),
        ("v0004's recipe, the reconstruction's frame", "trained"),
    ):
        _assert_gate_and_confirmation_cells(
            row(t, label), runs["validation", suffix], runs["confirm", suffix]
        )
    trained, shipped = (runs["confirm", s]["checkpoint"] for s in ("trained", "v0004"))
    assert (
        trained["data"]["seen_sites"] == shipped["data"]["seen_sites"]
    )  # the same sites, only the targets moved
    assert trained["train_metrics"]["steps_done"] == shipped["train_metrics"]["steps_done"] == 1200

    def correction_s(suffix: str) -> float:
        figures = runs["validation", suffix]["results"]
        return sum(
            figures[c]["element_masks"]["annotator"]["correction_s"] for c in ("clean", "reconstructed")
        )

    text = " ".join(readme_text().split())
    assert f"over both is {correction_s('trained'):.0f} s against {correction_s('v0004'):.0f} s" in text


def test_loop_on_reconstructions_in_the_frame_tables() -> None:
    """The rounds again with the truth in each reconstruction's frame, then with the annotator that may move an
    element whole: the same command as the rounds in the world but the registry."""

    def arguments(command: str) -> str:
        return re.sub(r"--(checkpoint|out) \S+ ?", "", command)

    world = results("vma_loop_masks_recon_rounds.json")
    for header, results_file, recon_column, bev_column in (
        ("round on reconstructions, in the frame", "vma_loop_masks_recon_rounds_frame.json", 4, None),
        ("round, elements moved whole", "vma_loop_masks_recon_rounds_move.json", 5, 4),
    ):
        t = table(header, "bench/vma_loop.py")
        assert_names_source(t, results_file, "bench/vma_loop.py")
        recorded = results(results_file)
        assert arguments(recorded["command"]) == arguments(world["command"])
        _check_rounds(t, recorded, recon_column, bev_column)


def test_loop_with_a_gate_on_ten_reconstructions_table() -> None:
    """The rounds with the annotator that moves elements whole again, eight more reconstructions validating: the
    same command but the gate's sites, and each round's figures as recorded."""
    t = table("round, gate on ten reconstructions", "bench/vma_loop.py")
    assert_names_source(t, "vma_loop_masks_recon_rounds_gate10.json", "bench/vma_loop.py")
    recorded = results("vma_loop_masks_recon_rounds_gate10.json")
    move = results("vma_loop_masks_recon_rounds_move.json")

    def arguments(command: str) -> str:
        return re.sub(r"--(checkpoint|out|gate-recon-site) \S+ ?", "", command)

    assert arguments(recorded["command"]) == arguments(move["command"])
    assert recorded["command"].count("--gate-recon-site") == 10
    _check_rounds(t, recorded, 5, 4)
    text = " ".join(readme_text().split())
    assert f"{recorded['seconds']:.0f} s in all against {move['seconds']:.0f} s" in text


def test_loop_rehearsing_reconstructions_table() -> None:
    """The ten-reconstruction gate's rounds again, rehearsing v0004's reconstructions: the same command but the
    rehearsal, each round as recorded."""
    t = table("round, rehearsing reconstructions", "bench/vma_loop.py")
    assert_names_source(t, "vma_loop_masks_recon_rounds_rehearse.json", "bench/vma_loop.py")
    recorded = results("vma_loop_masks_recon_rounds_rehearse.json")

    def arguments(command: str) -> str:
        return re.sub(r"--(checkpoint|out|replay-reconstructions|replay-share) \S+ ?", "", command)

    assert arguments(recorded["command"]) == arguments(
        results("vma_loop_masks_recon_rounds_gate10.json")["command"]
    )
    assert "--replay-reconstructions 6 --replay-share 0.5 " in recorded["command"]
    _check_rounds(t, recorded, 5, 4)


def _check_confident_rounds(t: MarkdownTable, recorded: dict[str, Any], map_tolerance: float = 0.0) -> None:
    """A loop table with the gate's confidence in a saving (column 4): the rounds as `_check_rounds` reads them,
    each confidence as recorded and as `saving_confidence` finds it again from the sites' own times, and each
    promotion as both gates decide it (the mAP gate at `map_tolerance`)."""
    _check_rounds(t, recorded, 6, 5)
    for entry in recorded["rounds"][1:]:
        cells = row(t, next(name for name in t.rows if name.split(" ")[0] == str(entry["round"])))
        gate = entry["gate"]
        again = saving_confidence(
            gate["current"]["review"]["per_site_correction_s"],
            gate["candidate"]["review"]["per_site_correction_s"],
        )
        assert again == gate["saving_confidence"], entry["round"]
        assert_shows(cells[4], [again], f"round {entry['round']} confidence")
        saved = gate["candidate"]["review"]["correction_s"] < gate["current"]["review"]["correction_s"]
        map_holds = gate["candidate"]["mean_ap"] >= gate["current"]["mean_ap"] - map_tolerance
        assert entry["promoted"] == (map_holds and saved and again >= TIME_CONFIDENCE), entry["round"]


def _confident_loop(header: str, name: str, command_of: str) -> tuple[dict[str, Any], str]:
    """A confident-saving loop table checked against its results file `name`, run with the command of the earlier
    run `command_of`; the recorded run and README's text (whitespace folded)."""
    t = table(header, "bench/vma_loop.py")
    assert_names_source(t, name, "bench/vma_loop.py")
    recorded = results(name)
    assert recorded["command"] == results(command_of)["command"]
    _check_confident_rounds(t, recorded)
    text = " ".join(readme_text().split())
    assert f"2 threads, {recorded['seconds']:.0f} s in all" in text
    return recorded, text


def test_loop_with_a_confident_saving_table() -> None:
    """The product's loop (no rehearsal) with the gate wanting a confident saving: the ten-reconstruction gate's
    command with the confidence at its default, each round as recorded, and what README says of round 3."""
    recorded, text = _confident_loop(
        "round, a confident saving",
        "vma_loop_masks_recon_rounds_confident.json",
        "vma_loop_masks_recon_rounds_gate10.json",
    )
    gate = recorded["rounds"][3]["gate"]
    current, candidate = (gate[k]["review"]["per_site_correction_s"] for k in ("current", "candidate"))
    dearer = sum(new > old for old, new in zip(current, candidate, strict=True))
    assert (dearer, len(current)) == (9, 13) and "costs the annotator on nine of the thirteen sites" in text


def test_loop_rehearsing_with_a_confident_saving_table() -> None:
    """The rehearsing rounds again with the confident-saving gate: the same command, each round as recorded, and
    round 2's candidate the one whose lower total the confidence refused."""
    recorded, text = _confident_loop(
        "round, rehearsing, a confident saving",
        "vma_loop_masks_recon_rounds_rehearse_confident.json",
        "vma_loop_masks_recon_rounds_rehearse.json",
    )
    gate = recorded["rounds"][2]["gate"]
    current, candidate = (gate[k]["review"] for k in ("current", "candidate"))
    saved = current["correction_s"] - candidate["correction_s"]
    share = 100 * saved / current["correction_s"]
    assert f"{saved:.0f} s ({share:.1f} %) less correction in all" in text
    faster = sum(
        new < old
        for old, new in zip(current["per_site_correction_s"], candidate["per_site_correction_s"], strict=True)
    )
    assert faster == 7 and "faster on only seven of the thirteen sites" in text
    assert f"a saving holds in {100 * gate['saving_confidence']:.0f} % of the resamples" in text
    assert not recorded["rounds"][2]["promoted"] and saved > 0


def test_rebuild_spread_table() -> None:
    """v0004's figures on three builds of each held-out site, the spread of each and of the total, as recorded, and
    the README's reading of them."""
    t = table("held-out site, three builds", "bench/rebuild_spread.py")
    assert_names_source(t, "rebuild_spread.json", "bench/rebuild_spread.py")
    recorded = results("rebuild_spread.json")
    assert "--seeds 0-2 " in recorded["command"] and recorded["checkpoint"].endswith("v0004")
    for site, entry in recorded["sites"].items():
        builds = entry["builds"]
        assert [b["seed"] for b in builds] == [0, 1, 2]
        cells = row(t, site.split("random-")[-1])
        assert_shows(cells[1], [b["correction_s"] for b in builds], f"{site} correction")
        assert_shows(cells[2], [entry["correction_s_spread"]], f"{site} spread")
        assert_shows(cells[3], [b["speed_up"] for b in builds], f"{site} speed-up")
        assert_shows(cells[4], [b["mean_ap"] for b in builds], f"{site} mAP")
    totals = recorded["total_correction_s"]
    assert_shows(row(t, "all five (total)")[1], totals, "total")
    spreads = [entry["correction_s_spread"] for entry in recorded["sites"].values()]
    share = 100 * (max(totals) - min(totals)) / min(totals)
    text = " ".join(readme_text().split())
    assert f"moves by {min(spreads):.0f}-{max(spreads):.0f} s from build to build" in text
    assert (
        f"total by {recorded['total_correction_s_spread']:.0f} s ({min(totals):.0f}-{max(totals):.0f} s, {share:.1f} %)"
        in text
    )
    assert f"{recorded['seconds']:.0f} s on 2 threads" in text


def test_candidates_the_ten_reconstruction_gate_refused_table() -> None:
    """Each refused candidate of the loop scored on the confirmation sites beside v0004, with the same command but
    the checkpoint; what the README concludes from them."""
    t = table("candidate the ten-reconstruction gate refused", "bench/vma_masks.py")
    loop = results("vma_loop_masks_recon_rounds_gate10.json")
    files = {"v0004 (kept)": "vma_masks_confirm_frame_v0004_border.json"}
    for entry in loop["rounds"][1:]:
        assert not entry["promoted"]
        files[f"{entry['candidate']} (round {entry['round']})"] = (
            f"vma_masks_confirm_gate10_{entry['candidate']}.json"
        )
    assert set(files) == set(t.rows)
    kept = results(files["v0004 (kept)"])

    for label, name in files.items():
        run = _check_confirmation_row(t, label, name, kept)
        if label != "v0004 (kept)":  # slower on both, lower mAP on the reconstructions, as the README says
            assert _confirmation_figures(run, "reconstructed") < _confirmation_figures(kept, "reconstructed")
            assert (
                _confirmation_figures(run, "reconstructed")[1]
                < _confirmation_figures(kept, "reconstructed")[1]
            )
            assert _confirmation_figures(run, "clean")[1] < _confirmation_figures(kept, "clean")[1]


def _confirmation_figures(run: dict[str, Any], condition: str) -> tuple[float, float]:
    """A `bench/vma_masks.py` run's mAP and speed-up of the element-mask network in one condition."""
    shown = run["results"][condition]["element_masks"]
    mean_ap = shown["observed_truth"]["mean_ap"] if condition == "reconstructed" else shown["mean_ap"]
    return mean_ap, shown["annotator"]["speed_up"]


def _check_confirmation_row(t: MarkdownTable, label: str, name: str, kept: dict[str, Any]) -> dict[str, Any]:
    """A candidate's row of a confirmation table (reconstructions, then BEV) as its results file `name` says, run
    with the kept model's command but the checkpoint; the run's figures."""
    assert_names_source(t, name, "bench/vma_masks.py")
    run = results(name)
    assert re.sub(r"--(checkpoint|out) \S+ ?", "", run["command"]) == re.sub(
        r"--(checkpoint|out) \S+ ?", "", kept["command"]
    )
    assert run["checkpoint"]["version"] == label.split()[0]
    cells = row(t, label)
    for cell, condition in ((cells[1], "reconstructed"), (cells[2], "clean")):
        assert_shows(cell, list(_confirmation_figures(run, condition)), f"{label} {condition}")
    return run


def test_candidate_the_confident_gate_refused_table() -> None:
    """The rehearsing run's refused round-2 candidate and v0004 on the confirmation sites of the rebuilt sites:
    level on the reconstructions, slower on BEV, as README says."""
    t = table("candidate the confident gate refused", "bench/vma_masks.py")
    loop = results("vma_loop_masks_recon_rounds_rehearse_confident.json")
    assert loop["rounds"][2]["candidate"] == "v0006" and not loop["rounds"][2]["promoted"]
    kept = results("vma_masks_confirm_rebuilt_v0004.json")
    _check_confirmation_row(t, "v0004 (kept)", "vma_masks_confirm_rebuilt_v0004.json", kept)
    run = _check_confirmation_row(
        t, "v0006 (round 2, rehearsing)", "vma_masks_confirm_rehearse_confident_v0006.json", kept
    )
    text = " ".join(readme_text().split())
    recon = [r["results"]["reconstructed"]["element_masks"]["annotator"] for r in (run, kept)]
    faster = sum(
        new < old
        for new, old in zip(recon[0]["per_site_correction_s"], recon[1]["per_site_correction_s"], strict=True)
    )
    assert faster == 4 and "faster on four of the six sites" in text
    assert f"({recon[0]['correction_s']:.0f} s of correction against {recon[1]['correction_s']:.0f} s" in text
    bev = [r["results"]["clean"]["element_masks"]["annotator"]["correction_s"] for r in (run, kept)]
    more = 100 * (bev[0] / bev[1] - 1)
    assert f"costs the annotator {more:.0f} % more ({bev[0]:.0f} s against {bev[1]:.0f} s)" in text


def _assert_gate_and_confirmation_cells(
    cells: list[str], validation: dict[str, Any], confirmation: dict[str, Any]
) -> None:
    """A row of mAP and speed-up of the element-mask network on the gate's BEV sites, the gate's reconstructions,
    the six confirmation reconstructions and the confirmation BEV sites (`bench/vma_masks.py` runs)."""
    for cell, run, condition in (
        (cells[1], validation, "clean"),
        (cells[2], validation, "reconstructed"),
        (cells[3], confirmation, "reconstructed"),
        (cells[4], confirmation, "clean"),
    ):
        shown = run["results"][condition]["element_masks"]
        mean_ap = shown["observed_truth"]["mean_ap"] if condition == "reconstructed" else shown["mean_ap"]
        assert_shows(cell, [mean_ap, shown["annotator"]["speed_up"]], f"{cells[0]} {condition}")


def _check_v0004_variants(t: MarkdownTable, variants: tuple[tuple[str, str], ...]) -> list[dict[str, Any]]:
    """Rows of a table of v0004 proposing with the proposer's code in several states (`bench/vma_masks.py` runs on
    the gate's sites and the confirmation sites, files `vma_masks_{validation,confirm}_frame_v0004{suffix}.json`,
    one command but the output); the element-mask figures on the confirmation reconstructions of each state."""
    for label, suffix in variants:
        for kind in ("validation", "confirm"):
            assert_names_source(t, f"vma_masks_{kind}_frame_v0004{suffix}.json", "bench/vma_masks.py")
        runs = [results(f"vma_masks_{kind}_frame_v0004{suffix}.json") for kind in ("validation", "confirm")]
        _assert_gate_and_confirmation_cells(row(t, label), *runs)
    for kind in ("validation", "confirm"):  # the same command, only the code between
        commands = {
            re.sub(r"--out \S+", "", results(f"vma_masks_{kind}_frame_v0004{suffix}.json")["command"]).strip()
            for _, suffix in variants
        }
        assert len(commands) == 1, commands
    return [
        results(f"vma_masks_confirm_frame_v0004{suffix}.json")["results"]["reconstructed"]["element_masks"]
        for _, suffix in variants
    ]


def test_boundary_ends_on_the_course_table() -> None:
    t = table("boundary ends, v0004 proposing", "bench/vma_masks.py")
    shown = _check_v0004_variants(
        t, (("as the refinement leaves them", ""), ("put back on the line's course", "_ends"))
    )
    corrections = [f"{figures['annotator']['correction_s']:.0f} s" for figures in shown]
    assert f"falls from {corrections[0]} to {corrections[1]}" in " ".join(readme_text().split())


def test_lines_carried_to_the_observed_edge_table() -> None:
    t = table("lines at the observed edge, v0004 proposing", "bench/vma_masks.py")
    shown = _check_v0004_variants(
        t, (("stopping where the masks stop", "_move"), ("carried on to the edge", "_border"))
    )
    text = " ".join(readme_text().split())
    corrections = [f"{figures['annotator']['correction_s']:.0f} s" for figures in shown]
    assert f"falls from {corrections[0]} to {corrections[1]}" in text
    boundary = [f"{figures['observed_truth']['class_ap']['boundary']:.3f}" for figures in shown]
    assert f"boundary AP rises from {boundary[0]} to {boundary[1]}" in text


def _check_end_to_end_rows(t: MarkdownTable, rows: tuple[tuple[str, str], ...]) -> None:
    """Rows of an end-to-end table on the default site and 9011 (files `{prefix}_{site}.json`): the annotator's
    speed-up in the world and in the reconstruction's frame, and the proposals' mAP against the observed truth."""
    for label, prefix in rows:
        cells = row(t, label)
        for cell, site in ((cells[1], "default"), (cells[2], "random-9011")):
            assert_names_source(t, f"{prefix}_{site}.json", "bench/end_to_end.py")
            run = results(f"{prefix}_{site}.json")
            figures = [
                run["annotator"]["speed_up"],
                run["annotator_in_reconstruction_frame"]["speed_up"],
                run["proposals_ap"]["observed_truth"]["mean_ap"],
            ]
            assert_shows(cell, figures, f"{label} {site}")


def test_lines_carried_to_the_observed_edge_end_to_end_table() -> None:
    t = table("end to end, lines at the observed edge", "bench/end_to_end.py")
    _check_end_to_end_rows(
        t,
        (
            ("stopping where the masks stop", "end_to_end_move"),
            ("carried on to the edge", "end_to_end_border"),
        ),
    )
    for site in ("default", "random-9011"):  # the same surface and annotator: only the proposals changed
        before, after = (
            results(f"{prefix}_{site}.json") for prefix in ("end_to_end_move", "end_to_end_border")
        )
        assert before["elevation"] == after["elevation"]
    boundary = results("end_to_end_border_default.json")["proposals_ap"]["observed_truth"]["class_ap"][
        "boundary"
    ]
    assert f"(boundary AP {boundary:.3f})" in " ".join(readme_text().split())


def test_boundary_ends_end_to_end_table() -> None:
    t = table("end to end, boundary ends", "bench/end_to_end.py")
    _check_end_to_end_rows(
        t,
        (
            ("as the refinement leaves them", "end_to_end_frame"),
            ("put back on the line's course", "end_to_end_ends"),
            ("the same, and the annotator may move an element whole (below)", "end_to_end_move"),
        ),
    )
    for site in (
        "default",
        "random-9011",
    ):  # the same surface: only the proposals, then the annotator, changed
        before, after, moved = (
            results(f"{prefix}_{site}.json")
            for prefix in ("end_to_end_frame", "end_to_end_ends", "end_to_end_move")
        )
        assert before["elevation"] == after["elevation"] == moved["elevation"]
        assert after["proposals_ap"] == moved["proposals_ap"]


def test_paint_placement_table() -> None:
    t = table("site, divider length", "bench/paint_placement.py")
    assert_names_source(t, "paint_placement.json", "bench/paint_placement.py")
    recorded = results("paint_placement.json")
    displaced = [
        (Path(site["site"]).name.removeprefix("random-"), divider)
        for site in recorded["sites"]
        for divider in site["dividers"]
        if divider["paint_offset_m"] is not None and abs(divider["paint_offset_m"]) > recorded["displaced_m"]
    ]
    assert len(displaced) == len(t.rows)
    for (name, divider), (label, cells) in zip(displaced, t.rows.items(), strict=True):
        assert label.split(",")[0] == name
        assert_shows(label, [*([] if name == "default" else [int(name)]), divider["length_m"]], label)
        assert_shows(cells[1], [divider["paint_offset_m"]], label)
        assert_shows(cells[2], [divider["height_error_m"] * 100], label)
        assert_shows(cells[3], [divider["distance_from_trajectory_m"]], label)
    painted = sum(site["with_paint"] for site in recorded["sites"])
    assert f"Of {painted} dividers with paint in the rasters, {len(displaced)} lie" in " ".join(
        readme_text().split()
    )


def test_moving_an_element_whole_table() -> None:
    t = table("scripted annotator, reconstructions", "bench/vma_masks.py")
    for label, suffix in (("vertex edits only", "_ends"), ("may move an element whole first", "_move")):
        cells = row(t, label)
        for cell, kind in ((cells[1], "validation"), (cells[2], "confirm")):
            name = f"vma_masks_{kind}_frame_v0004{suffix}.json"
            assert_names_source(t, name, "bench/vma_masks.py")
            shown = results(name)["results"]["reconstructed"]
            speed_ups = [shown[p]["annotator"]["speed_up"] for p in ("rule_based", "element_masks")]
            assert_shows(cell, speed_ups, f"{label} {kind}")
    corrections = [
        results(f"vma_masks_confirm_frame_v0004{s}.json")["results"]["reconstructed"]["element_masks"][
            "annotator"
        ]["correction_s"]
        for s in ("_ends", "_move")
    ]
    text = " ".join(readme_text().split())
    assert f"v0004 falls from {corrections[0]:.0f} s to {corrections[1]:.0f} s" in text


def test_crossing_fit_table() -> None:
    """Both crossing fits on the tuning and the confirmation reconstructions, as recorded, and the BEV figures the
    README quotes for the change."""
    t = table("crossings on reconstructions, v0004 proposing", "bench/crossing_fit.py")
    for name in ("crossing_fit_tuning.json", "crossing_fit_confirm.json"):
        assert_names_source(t, name, "bench/crossing_fit.py")
    tuning, confirm = results("crossing_fit_tuning.json"), results("crossing_fit_confirm.json")
    assert_seeds(tuning, range(9113, 9124))
    assert len(confirm["sites"]) == 6 and "data/synthetic/default" in confirm["sites"]
    for label, fit in (
        ("smallest rectangle round the stripes", "rectangle"),
        ("block read from the stripes", "stripes"),
    ):
        cells = row(t, label)
        for column, recorded in ((1, tuning), (3, confirm)):
            figures_of = recorded["fits"][fit]
            shown = [figures_of["mean_iou"], figures_of["mean_chamfer_m"], figures_of["acceptable_share"]]
            assert_shows(cells[column], shown, f"{label} crossings")
            assert_shows(
                cells[column + 1], [figures_of["correction_s"], figures_of["speed_up"]], f"{label} time"
            )
    further = table("crossings held out further, v0004 proposing", "bench/crossing_fit.py")
    for column, name in ((1, "crossing_fit_fresh.json"), (3, "crossing_fit_9007_9011.json")):
        assert_names_source(further, name, "bench/crossing_fit.py")
        for label, fit in (
            ("smallest rectangle round the stripes", "rectangle"),
            ("block read from the stripes", "stripes"),
        ):
            figures_of = results(name)["fits"][fit]
            shown = [figures_of["mean_iou"], figures_of["mean_chamfer_m"], figures_of["acceptable_share"]]
            assert_shows(row(further, label)[column], shown, f"{name} {label} crossings")
            assert_shows(
                row(further, label)[column + 1],
                [figures_of["correction_s"], figures_of["speed_up"]],
                f"{name} {label} time",
            )
    fresh = results("crossing_fit_fresh.json")["fits"]
    lost = [
        s - r
        for s, r in zip(
            fresh["stripes"]["per_site_correction_s"],
            fresh["rectangle"]["per_site_correction_s"],
            strict=True,
        )
    ]
    assert len(lost) == 10 and min(lost) > 0  # "every one of the ten loses time"
    assert (
        f"({sum(lost):.0f} s in all, {100 * (sum(lost) / fresh['rectangle']['correction_s']):.0f} %)"
        in " ".join(readme_text().split())
    )
    saved = tuning["fits"]["rectangle"]["correction_s"] - tuning["fits"]["stripes"]["correction_s"]
    text = " ".join(readme_text().split())
    assert (
        f"the annotator saves {saved:.0f} s ({100 * (1 - tuning['correction_ratio_stripes_to_rectangle']):.0f} %)"
        in text
    )
    before = results("vma_masks_confirm_rebuilt_v0004.json")["results"]
    after = results("vma_masks_confirm_crossing_fit_v0004.json")["results"]
    for condition in ("clean", "degraded"):
        old, new = before[condition]["element_masks"], after[condition]["element_masks"]
        assert f"{old['mean_ap']:.4f} -> {new['mean_ap']:.4f}" in text
        assert f"{old['class_ap']['ped_crossing']:.3f} to {new['class_ap']['ped_crossing']:.3f}" in text
        assert old["annotator"]["speed_up"] == pytest.approx(new["annotator"]["speed_up"])


def test_boundary_evidence_table() -> None:
    """The three boundary settings on the tuning, confirmation, gate-validation and fresh reconstructions, as
    recorded, and the totals the README quotes."""
    t = table("boundaries on reconstructions, v0004 proposing", "bench/boundary_evidence.py")
    files = {
        "tuning 9113-9123": "boundary_evidence_tuning.json",
        "confirmation, six sites": "boundary_evidence_confirm.json",
        "gate validation 9007, 9011": "boundary_evidence_9007_9011.json",
        "fresh 9201-9210": "boundary_evidence_fresh.json",
    }
    before = after = 0.0
    for _, label, cells, recorded in recorded_rows(t, files, "bench/boundary_evidence.py"):
        assert f"({recorded['settings']['road_edge']['boundaries']}" in label
        for column, setting in ((1, "network_band"), (2, "road_edge"), (3, "across_gap")):
            assert_shows_boundaries(cells[column], recorded["settings"][setting], f"{label} {setting}")
        for column, setting in ((4, "network_band"), (5, "across_gap")):
            assert_shows_saving(cells[column], recorded["against_road_edge"][setting], f"{label} {setting}")
        before += recorded["settings"]["road_edge"]["correction_s"]
        after += recorded["settings"]["network_band"]["correction_s"]
    for prefix, seeds in (("tuning 9113-9123", range(9113, 9124)), ("fresh 9201-9210", range(9201, 9211))):
        assert_seeds(results(files[prefix]), seeds)
    text = " ".join(readme_text().split())
    assert f"falls from {before:,.0f} s to {after:,.0f} s ({100 * (1 - after / before):.0f} %)" in text
    edge = results("vma_masks_confirm_rebuilt_v0004.json")["results"]
    band = results("vma_masks_confirm_band_v0004.json")["results"]
    old, new = edge["reconstructed"]["element_masks"], band["reconstructed"]["element_masks"]
    assert old["observed_truth"]["mean_ap"] == pytest.approx(new["observed_truth"]["mean_ap"], abs=5e-4)
    assert f"unchanged at {new['observed_truth']['mean_ap']:.3f}" in text
    assert f"(boundary AP {new['observed_truth']['class_ap']['boundary']:.3f} both ways" in text
    assert f"goes from {old['annotator']['speed_up']:.2f}x to {new['annotator']['speed_up']:.2f}x" in text
    for condition in ("clean", "degraded"):
        assert edge[condition]["element_masks"]["mean_ap"] == band[condition]["element_masks"]["mean_ap"]


def test_narrower_crossing_table() -> None:
    """The rectangle against the narrower block on every set of reconstructions, as recorded."""
    t = table("crossings, the narrower block, v0004 proposing", "bench/crossing_fit.py")
    files = {
        "tuning 9113-9123": "crossing_fit_narrower_tuning.json",
        "fresh 9211-9220": "crossing_fit_narrower_fresh2.json",
        "confirmation, six sites": "crossing_fit_narrower_confirm.json",
        "gate validation 9007, 9011": "crossing_fit_narrower_9007_9011.json",
        "fresh 9201-9210": "crossing_fit_narrower_fresh.json",
    }
    before = after = 0.0
    for prefix, label, cells, recorded in recorded_rows(t, files, "bench/crossing_fit.py"):
        for column, fit in ((1, "rectangle"), (2, "narrower")):
            shown = recorded["fits"][fit]
            assert_shows(
                cells[column],
                [shown["mean_iou"], shown["acceptable_share"], shown["correction_s"], shown["speed_up"]],
                f"{label} {fit}",
            )
        assert_shows_saving(cells[3], recorded["against_rectangle"]["narrower"], f"{label} ratio")
        if not prefix.startswith("tuning"):
            before += recorded["fits"]["rectangle"]["correction_s"]
            after += recorded["fits"]["narrower"]["correction_s"]
    assert_seeds(results(files["fresh 9211-9220"]), range(9211, 9221))
    text = " ".join(readme_text().split())
    assert f"it is level ({before:,.0f} s -> {after:,.0f} s)" in text


def test_end_to_end_band_sentence() -> None:
    """The default site's end-to-end figures with the network's band, and the run before, as recorded."""
    text = " ".join(readme_text().split())
    now, before = results("end_to_end_band_default.json"), results("end_to_end_border_default.json")
    world, frame = now["annotator"]["speed_up"], now["annotator_in_reconstruction_frame"]["speed_up"]
    assert f"annotator is {world:.2f}x faster than drawing in the world frame and {frame:.2f}x in the" in text
    old_world, old_frame = (
        before["annotator"]["speed_up"],
        before["annotator_in_reconstruction_frame"]["speed_up"],
    )
    assert (
        f"against {old_world:.2f}x and {old_frame:.2f}x in `bench/results/end_to_end_border_default.json`"
        in text
    )
    new_ap, old_ap = (r["proposals_ap"]["observed_truth"]["mean_ap"] for r in (now, before))
    assert f"observed truth {new_ap:.3f} ({old_ap:.3f} before)" in text
    assert now["proposed_by"] == ["vma-masks-v0004"]
    assert "0.04x short" in text and round(2.2 - frame, 2) == 0.04


def test_boundary_offset_table() -> None:
    """The band alone and the product's boundaries moved off the road, on the gate and five held-out sets, as
    recorded; the product's offset is the gate's median, and the held-out totals the README quotes."""
    t = table("boundaries moved off the road, v0004 proposing", "bench/boundary_offset.py")
    files = set_files("boundary_offset")
    seeds = {
        "gate 9113-9123": range(9113, 9124),
        "fresh 9201-9210": range(9201, 9211),
        "fresh 9211-9220": range(9211, 9221),
        "fresh 9221-9230": range(9221, 9231),
        "gate validation 9007, 9011": (9007, 9011),
    }
    band = product = 0.0
    for prefix, label, cells, recorded in recorded_rows(t, files, "bench/boundary_offset.py"):
        if prefix in seeds:
            assert_seeds(recorded, seeds[prefix])
        assert f"({recorded['settings']['band']['boundaries']}" in label
        for column, setting in ((1, "band"), (2, "product")):
            assert_shows_boundaries(cells[column], recorded["settings"][setting], f"{label} {setting}")
        assert_shows_saving(cells[3], recorded["against_band"]["product"], label)
        offsets = recorded["band_offsets"]
        assert_shows(cells[4], [offsets["proposal_median_roadward_m"], offsets["stations"]], label)
        assert recorded["product_outward_m"] == MaskInferenceConfig().boundary_outward_m
        assert recorded["against_band"]["product"]["correction_ratio"] < 1.0  # "every held-out set saves"
        if prefix != "gate 9113-9123":
            band += recorded["settings"]["band"]["correction_s"]
            product += recorded["settings"]["product"]["correction_s"]
    gate = results("boundary_offset_gate.json")["band_offsets"]
    assert round(gate["proposal_median_roadward_m"], 2) == MaskInferenceConfig().boundary_outward_m
    text = " ".join(readme_text().split())
    assert f"falls from {band:,.0f} s to {product:,.0f} s ({100 * (1 - product / band):.1f} %)" in text
    assert f"the road's edge lies a median {gate['road_edge_median_roadward_m']:.2f} m inside" in text
    assert f"correlate at {gate['proposal_road_edge_correlation']:.2f}" in text
    band_e2e, outward_e2e = (
        results("end_to_end_band_default.json"),
        results("end_to_end_outward_default.json"),
    )
    quoted = (
        f"{outward_e2e['annotator']['speed_up']:.2f}x faster than drawing in the world frame and "
        f"{outward_e2e['annotator_in_reconstruction_frame']['speed_up']:.2f}x in the reconstruction's frame, against "
        f"{band_e2e['annotator']['speed_up']:.2f}x and {band_e2e['annotator_in_reconstruction_frame']['speed_up']:.2f}x"
    )
    assert quoted in text
    kinds = ("accept", "fix", "reject", "drawn")
    now, before = (r["annotator"]["corrected"]["counts"] for r in (outward_e2e, band_e2e))
    counts = f"({now['accept']} accepted, {now['fix']} fixed, {now['reject']} rejected, {now['drawn']} drawn against "
    assert counts + ", ".join(str(before[k]) for k in kinds) + ")" in text


def test_surface_range_table() -> None:
    """The height error by distance from the track on both fresh sets, as recorded, and the curvature range the
    README quotes."""
    t = table("distance from the camera track", "bench/surface_range.py")
    recorded = {
        "9201-9210": results("surface_range_fresh.json"),
        "9221-9230": results("surface_range_fresh3.json"),
    }
    for name in ("surface_range_fresh.json", "surface_range_fresh3.json"):
        assert_names_source(t, name, "bench/surface_range.py")
    for seeds, report in zip(("9201-9210", "9221-9230"), recorded.values(), strict=True):
        first, last = (int(s) for s in seeds.split("-"))
        assert_seeds(report, range(first, last + 1))
    columns = [("9201-9210", "reconstruction"), ("9201-9210", "extrapolation")]
    columns += [("9221-9230", "reconstruction"), ("9221-9230", "extrapolation")]
    bands = recorded["9201-9210"]["pooled"]["reconstruction"]
    assert len(t.rows) == len(bands)
    for k, band in enumerate(bands):
        label, cells = row_starting(t, f"{band['band_m'][0]}-{band['band_m'][1]} m")
        for column, (seeds, surface) in enumerate(columns, start=1):
            row = recorded[seeds]["pooled"][surface][k]
            assert_shows(
                cells[column],
                [100 * row["median_m"], 100 * row["rms_m"], row["beyond_4cm_share"]],
                f"{label} {seeds} {surface}",
            )
    curvature = [
        site["lateral_curvature"]["4_m"]
        for report in recorded.values()
        for site in report["per_site"].values()
    ]
    assert len(curvature) == 20 and all(c["median_per_m"] < 0 for c in curvature)
    text = " ".join(readme_text().split())
    steepest = min(c["median_per_m"] for c in curvature)
    flattest = max(c["median_per_m"] for c in curvature)
    share = (min(c["negative_share"] for c in curvature), max(c["negative_share"] for c in curvature))
    assert f"a median of {flattest:.5f} to {steepest:.4f} per metre per site" in text
    assert f"negative at {100 * share[0]:.0f}-{100 * share[1]:.0f} % of the key frames" in text


def test_annotator_split_table() -> None:
    """The annotator without and with the editor's split on the same proposals, as recorded; its "without" column
    is the boundary-offset table's product, and the held-out totals are the ones the README quotes."""
    t = table("the editor's split, v0004 proposing", "bench/annotator_split.py")
    files = set_files("annotator_split")
    without = with_split = 0.0
    for prefix, label, cells, recorded in recorded_rows(t, files, "bench/annotator_split.py"):
        shown = recorded["settings"]
        for column, setting in ((1, "no_split"), (2, "split")):
            figure = shown[setting]
            assert_shows(cells[column], [figure["correction_s"], figure["speed_up"], figure["drawn"]], label)
        assert_shows(cells[2][cells[2].index("drawn") :], [shown["split"]["splits"]], label)
        assert_shows_saving(cells[3], recorded["against_no_split"]["split"], label)
        offset = results(files[prefix].replace("annotator_split", "boundary_offset"))
        assert shown["no_split"]["per_site_correction_s"] == pytest.approx(
            offset["settings"]["product"]["per_site_correction_s"]
        )
        if prefix != "gate 9113-9123":
            without += shown["no_split"]["correction_s"]
            with_split += shown["split"]["correction_s"]
    text = " ".join(readme_text().split())
    saving = 100 * (1 - with_split / without)
    assert f"falls from {without:,.0f} s to {with_split:,.0f} s ({saving:.2f} %)" in text


def test_divider_carry_table() -> None:
    """Dividers carried as before and as the product carries them through the dash gap, as recorded; the
    product's settings are the ones the bench measured, and the held-out totals the README quotes."""
    t = table("dividers carried through the dash gap, v0004 proposing", "bench/divider_carry.py")
    files = set_files("divider_carry")
    before = product = unseen_before = unseen_product = 0.0
    for prefix, label, cells, recorded in recorded_rows(t, files, "bench/divider_carry.py"):
        shown = recorded["settings"]
        assert (
            f"({shown['before']['dividers']})" in label
            or f"({shown['before']['dividers']} dividers)" in label
        )
        for column, setting in ((1, "before"), (2, "product")):
            figure = shown[setting]
            expected = [
                figure["acceptable_share"],
                figure["mean_chamfer_m"],
                figure["correction_s"],
                figure["speed_up"],
            ]
            assert_shows(cells[column], expected, f"{label} {setting}")
        assert_shows_saving(cells[3], recorded["against_before"]["product"], label)
        assert recorded["against_before"]["product"]["correction_ratio"] <= 1.0  # "no set loses"
        if prefix != "gate 9113-9123":
            before += shown["before"]["correction_s"]
            product += shown["product"]["correction_s"]
        if prefix not in ("gate 9113-9123", "fresh 9201-9210"):  # not looked at while choosing
            unseen_before += shown["before"]["correction_s"]
            unseen_product += shown["product"]["correction_s"]
    config = MaskInferenceConfig()
    assert (config.divider_border_reach_m, config.divider_course_fit_m) == (6.0, 4.0)
    end_to_end = results("end_to_end_carry_split_default.json")
    before_e2e = results("end_to_end_outward_default.json")
    for frame in ("annotator", "annotator_in_reconstruction_frame"):  # "neither moves a decision"
        counts = dict(end_to_end[frame]["corrected"]["counts"])
        assert counts.pop("splits") == 0 and counts == before_e2e[frame]["corrected"]["counts"]
        assert end_to_end[frame]["corrected"]["total_s"] == pytest.approx(
            before_e2e[frame]["corrected"]["total_s"]
        )
    text = " ".join(readme_text().split())
    assert f"falls from {before:,.0f} s to {product:,.0f} s ({100 * (1 - product / before):.2f} %)" in text
    assert (
        f"the 28 not looked at while choosing from {unseen_before:,.0f} s to {unseen_product:,.0f} s" in text
    )


def test_more_reconstructions_table() -> None:
    """v0004 and the two candidates trained on 36 reconstructions (every site alike; half the crops from the
    reconstructions), the product's tracing, as recorded; the held-out totals and the confirmation mAPs the README
    quotes."""
    t = table("more reconstructions, the product's tracing", "bench/divider_carry.py")
    shipped = candidate = shared = 0.0
    for prefix, suffix in HELD_OUT_SETS.items():
        label, cells = row_starting(t, prefix)
        before = results(f"divider_carry_{suffix}.json")["settings"]["product"]
        after = results(f"divider_carry_more_recon_{suffix}.json")
        half = results(f"divider_carry_share_{suffix}.json")
        assert after["checkpoint"] == "data/vma/s4reg/v0001"  # the candidates, not in the repository
        assert half["checkpoint"] == "data/vma/s4reg2/v0001"
        for column, figure in (
            (1, before),
            (2, after["settings"]["product"]),
            (3, half["settings"]["product"]),
        ):
            assert_shows(cells[column], [figure["correction_s"], figure["speed_up"]], label)
        if prefix != "gate 9113-9123":
            shipped += before["correction_s"]
            candidate += after["settings"]["product"]["correction_s"]
            shared += half["settings"]["product"]["correction_s"]
    text = " ".join(readme_text().split())
    for total in (candidate, shared):
        assert f"falls from {shipped:,.0f} s to {total:,.0f} s ({100 * (1 - total / shipped):.1f} %)" in text
    new, old, half_ap = (
        results(f)["results"]
        for f in (
            "vma_masks_confirm_more_recon.json",
            "vma_masks_confirm_v0004_carry.json",
            "vma_masks_confirm_recon_share.json",
        )
    )
    mine, theirs = new["reconstructed"]["element_masks"], old["reconstructed"]["element_masks"]
    quoted = (
        f"{mine['observed_truth']['mean_ap']:.3f} against {theirs['observed_truth']['mean_ap']:.3f}, on the clean BEV "
        f"sites 5000-5004 {new['clean']['element_masks']['mean_ap']:.3f} against "
        f"{old['clean']['element_masks']['mean_ap']:.3f}"
    )
    assert quoted in text

    def maps(r: dict[str, Any]) -> list[float]:
        masks = {kind: r[kind]["element_masks"] for kind in ("reconstructed", "clean", "degraded")}
        return [
            masks["reconstructed"]["observed_truth"]["mean_ap"],
            masks["clean"]["mean_ap"],
            masks["degraded"]["mean_ap"],
        ]

    ours, v0004 = maps(half_ap), maps(old)
    assert all(
        a > b for a, b in zip(ours, v0004, strict=True)
    )  # "its proposal mAP rises wherever it is scored"
    assert (
        f"reconstructions {ours[0]:.3f} against v0004's {v0004[0]:.3f}, the clean BEV sites {ours[1]:.3f} against "
        f"{v0004[1]:.3f}, damaged {ours[2]:.3f} against {v0004[2]:.3f}"
    ) in text


def test_share_candidate_gate_runs() -> None:
    """The share-0.5 candidate on the gate's validation sites beside v0004, and the paired saving over the held-out
    reconstructions, as the README quotes them; the pairs are the divider-carry files the table above shows."""
    text = " ".join(readme_text().split())
    for name in ("vma_masks_validation_share_share.json", "vma_masks_validation_share_v0004.json"):
        assert f"bench/results/{name}" in text
    ours, v0004 = (results(f"vma_masks_validation_share_{n}.json") for n in ("share", "v0004"))
    assert "--checkpoint data/vma/s4reg2/v0001" in ours["command"]
    assert ours["checkpoint"]["data"]["reconstruction_share"] == 0.5
    assert v0004["checkpoint"]["version"] == "v0004"
    mine, theirs = ours["results"], v0004["results"]

    def masks(r: dict[str, Any], kind: str) -> dict[str, Any]:
        return r[kind]["element_masks"]

    assert (
        f"clean {masks(mine, 'clean')['mean_ap']:.3f} against {masks(theirs, 'clean')['mean_ap']:.3f}, damaged "
        f"{masks(mine, 'degraded')['mean_ap']:.3f} against {masks(theirs, 'degraded')['mean_ap']:.3f}, the "
        f"reconstructions of 9007 and 9011 {masks(mine, 'reconstructed')['observed_truth']['mean_ap']:.3f} against "
        f"{masks(theirs, 'reconstructed')['observed_truth']['mean_ap']:.3f}"
    ) in text
    clean = [masks(r, "clean")["annotator"] for r in (mine, theirs)]
    both = [
        masks(r, "clean")["annotator"]["correction_s"]
        + masks(r, "reconstructed")["annotator"]["correction_s"]
        for r in (mine, theirs)
    ]
    assert (
        f"needs {clean[0]['correction_s']:.0f} s on the clean BEV sites against {clean[1]['correction_s']:.0f} s "
        f"({clean[0]['speed_up']:.2f}x against {clean[1]['speed_up']:.2f}x), {both[0]:.0f} s over both kinds against "
        f"{both[1]:.0f} s"
    ) in text
    assert both[0] > both[1]  # "the gate, which asks a lower total, keeps it out"

    share, more = (results(f"paired_saving_{n}.json") for n in ("share", "more_recon"))
    for paired, stem in ((share, "divider_carry_share"), (more, "divider_carry_more_recon")):
        assert sorted(paired["sets"]) == sorted(s for s in HELD_OUT_SETS.values() if s != "gate")
        for suffix, row in paired["sets"].items():
            assert row["files"] == [
                f"bench/results/divider_carry_{suffix}.json",
                f"bench/results/{stem}_{suffix}.json",
            ]
        assert paired["pooled"]["sites"] == 38
        assert paired["pooled"]["saving_confidence"] < 0.9  # neither is a confident saving
    pooled = share["pooled"]
    assert (
        f"faster on {pooled['faster_sites']} sites and slower on {pooled['slower_sites']}, and a saving holds in "
        f"{100 * pooled['saving_confidence']:.0f} % of the paired bootstrap resamples"
    ) in text
    others = [row["saving_confidence"] for name, row in share["sets"].items() if name != "fresh"]
    assert (
        f"({share['sets']['fresh']['saving_confidence']:.2f} there, {min(others):.2f}-{max(others):.2f} on each"
        in text
    )
    first = more["pooled"]
    assert (
        f"holds in {100 * first['saving_confidence']:.1f} % (`bench/results/paired_saving_more_recon.json`, "
        f"{first['faster_sites']} faster, {first['slower_sites']} slower)"
    ) in text


def image_resolution_rows(t: MarkdownTable, figures: dict[str, Any], labels: dict[str, str]) -> None:
    """Each build's row of an image-resolution table: mAP (divider AP), correction and speed-up, and the road's
    height error at 8-10, 10-12 and 12-15 m from the track (medians, then RMS, in cm)."""
    for build, label in labels.items():
        shown = figures[build]
        bands = shown["height_error_by_distance"][4:7]
        assert [b["band_m"] for b in bands] == [[8, 10], [10, 12], [12, 15]]
        cells = row(t, label)
        assert_shows(cells[1], [shown["observed_truth_map"], shown["class_ap"]["divider"]], label)
        annotator = shown["annotator"]
        assert_shows(cells[2], [annotator["correction_s"], annotator["speed_up"]], label)
        heights = [100 * b["median_m"] for b in bands] + [100 * b["rms_m"] for b in bands]
        assert_shows(cells[3], heights, label)


def pairs_faster(gain: dict[str, Any], pairs: int, decimals: int) -> str:
    """How the README states the larger images' saving over the pairs: on how many faster, and how sure."""
    confidence = 100 * gain["saving_confidence"]
    return (
        f"(faster on {gain['faster_pairs']} of the {pairs}, a saving in {confidence:.{decimals}f} % of the paired "
        "resamples)"
    )


def test_image_resolution_table() -> None:
    """The held-out layouts at 256x144 and at 512x288, v0004 proposing: the table and the sentence after it; the
    256x144 builds are the reconstructions of the divider-carry table's fresh 9211-9230 sets, site for site."""
    t = table("image size, 20 held-out layouts 9211-9230", "bench/image_resolution.py")
    assert_names_source(t, "image_resolution_512.json", "bench/image_resolution.py")
    figures = results("image_resolution_512.json")
    assert figures["checkpoint"].endswith("models/vma/element_masks/checkpoints/v0004")
    assert [pair["image_sizes"] for pair in figures["pairs"]] == [[[256, 144], [512, 288]]] * 20
    image_resolution_rows(t, figures, {"low": "256x144 (the tiny preset)", "high": "512x288"})
    same = [
        t
        for suffix in ("fresh2", "fresh3")
        for t in results(f"divider_carry_{suffix}.json")["settings"]["product"]["per_site_correction_s"]
    ]
    assert figures["low"]["annotator"]["per_site_correction_s"] == pytest.approx(same)
    gain = figures["high_against_low"]
    text = " ".join(readme_text().split())
    assert f"in {100 * (1 - gain['correction_ratio']):.0f} % less time {pairs_faster(gain, 20, 0)}" in text


def test_image_resolution_1024_table() -> None:
    """The twenty layouts at 256x144, 512x288 and 1024x576 from the two runs that pair 1024x576 with each smaller
    size: the 1024x576 builds score the same in both, and the two smaller ones as in the 512x288 table."""
    t = table("image size, 20 held-out layouts 9211-9230, three builds each", "bench/image_resolution.py")
    for name in ("image_resolution_256_1024.json", "image_resolution_1024.json"):
        assert_names_source(t, name, "bench/image_resolution.py")
    from_256, from_512 = results("image_resolution_256_1024.json"), results("image_resolution_1024.json")
    assert [p["image_sizes"] for p in from_256["pairs"]] == [[[256, 144], [1024, 576]]] * 20
    assert [p["image_sizes"] for p in from_512["pairs"]] == [[[512, 288], [1024, 576]]] * 20
    at_1024 = from_256["high"]["annotator"]
    assert at_1024["per_site_correction_s"] == from_512["high"]["annotator"]["per_site_correction_s"]
    twenty = results("image_resolution_512.json")
    for paired, same_build in ((from_256, "low"), (from_512, "high")):  # its smaller build is the 512 run's
        shown = paired["low"]["annotator"]["per_site_correction_s"]
        assert shown == pytest.approx(twenty[same_build]["annotator"]["per_site_correction_s"])
    image_resolution_rows(t, from_256, {"low": "256x144 (the tiny preset)", "high": "1024x576"})
    image_resolution_rows(t, from_512, {"low": "512x288"})
    text = " ".join(readme_text().split())
    assert (
        f"corrects the twenty layouts in {at_1024['correction_s']:,.0f} s against {at_1024['drawing_s']:,.0f} s of "
        f"drawing: {at_1024['speed_up']:.2f}x, above issue 26's 2.5x"
    ) in text
    assert at_1024["speed_up"] >= 2.5
    gain = from_512["high_against_low"]
    against_256 = from_256["high_against_low"]["correction_ratio"]
    assert (
        f"saves {100 * (1 - gain['correction_ratio']):.0f} % {pairs_faster(gain, 20, 0)}, against 256x144 "
        f"{100 * (1 - against_256):.0f} %"
    ) in text
    per_site = at_1024["per_site_correction_s"]
    assert (
        f"runs from {min(per_site):.0f} to {max(per_site):.0f} s (median {statistics.median(per_site):.0f} s); the six "
        f"layouts 9221-9226 of the previous stop's first 1024x576 run take {sum(per_site[10:16]):.0f} s"
    ) in text
    longer = from_256["low"]["annotator"]["correction_s"] / at_1024["correction_s"] - 1
    assert f"where the same layouts take {100 * longer:.0f} % longer" in text
    assert (  # the pointer under VMA proposals
        f"are corrected {100 * (1 - twenty['high_against_low']['correction_ratio']):.0f} % faster at 512x288 and "
        f"{100 * (1 - against_256):.0f} % faster at 1024x576, where the shipped v0004 reaches "
        f"{at_1024['speed_up']:.2f}x"
    ) in text


def test_rules_at_larger_images_table() -> None:
    """The rule-based proposer and v0004 on the twenty held-out layouts' reconstructions at each image size, from
    `bench/vma_masks.py`: each row's figures and margin; v0004's figures are the image-resolution runs' own."""
    t = table("reconstructions of 20 held-out layouts 9211-9230", "bench/vma_masks.py")
    at_512, at_1024 = results("image_resolution_512.json"), results("image_resolution_1024.json")
    sizes = {  # row label -> results file, the builds' site prefix, the same builds in the image-resolution runs
        "256x144": ("vma_masks_resolution_256.json", "random", at_512["low"]),
        "512x288": ("vma_masks_resolution_512.json", "random512", at_512["high"]),
        "1024x576": ("vma_masks_resolution_1024.json", "random1024", at_1024["high"]),
    }
    margins = {}
    for size, (name, tag, same_as) in sizes.items():
        assert_names_source(t, name, "bench/vma_masks.py")
        run = results(name)
        assert run["checkpoint"]["version"] == "v0004"
        assert f"--recon-site data/synthetic/{tag}-9211 " in run["command"]
        assert run["command"].count("--recon-site") == 20
        scored = run["results"]["reconstructed"]
        rules, network = scored["rule_based"], scored["element_masks"]
        cells = row(t, size)
        for cell, shown in ((cells[1], rules), (cells[2], network)):
            truth = shown["observed_truth"]
            assert_shows(
                cell, [truth["mean_ap"], truth["class_ap"]["divider"], shown["annotator"]["speed_up"]], size
            )
        margin = run["map_margin_over_rule_based"]["reconstructed"]
        assert_shows(cells[3], [margin], size)
        assert network["observed_truth"]["mean_ap"] == pytest.approx(same_as["observed_truth_map"])
        assert network["annotator"]["correction_s"] == pytest.approx(same_as["annotator"]["correction_s"])
        margins[size] = margin
    assert min(margins.values()) >= 0.05  # "at least 0.05 above them at every size"
    text = " ".join(readme_text().split())
    low, high = (results(sizes[size][0])["results"]["reconstructed"] for size in ("256x144", "1024x576"))

    def gain(proposer: str) -> float:
        return float(high[proposer]["observed_truth"]["mean_ap"] - low[proposer]["observed_truth"]["mean_ap"])

    assert f"the rules gain {gain('rule_based'):.3f} mAP and the network {gain('element_masks'):.3f}" in text
    boundary = [high[p]["observed_truth"]["class_ap"]["boundary"] for p in ("rule_based", "element_masks")]
    assert f"road boundaries score {boundary[0]:.3f} AP against the network's {boundary[1]:.3f}" in text


def test_training_on_larger_images_sentence() -> None:
    """v0004 and its two 600-step continuations (on 256x144 and on 512x288 reconstructions of 9101-9112), scored on
    the twenty held-out layouts at 512x288, as the README quotes them; v0004's figure repeats the image-resolution
    table's 512x288 row."""
    text = " ".join(readme_text().split())
    runs = {k: results(f"divider_carry_512_{k}.json") for k in ("v0004", "recon256", "recon512")}
    assert runs["v0004"]["checkpoint"].endswith("checkpoints/v0004")
    assert all(
        run["sites"] == [f"data/synthetic/random512-{s}" for s in range(9211, 9231)] for run in runs.values()
    )
    shown = {k: run["settings"]["product"] for k, run in runs.items()}
    assert shown["v0004"]["per_site_correction_s"] == pytest.approx(
        results("image_resolution_512.json")["high"]["annotator"]["per_site_correction_s"]
    )

    def said(figures: dict[str, Any]) -> str:
        return f"{figures['correction_s']:,.0f} s ({figures['speed_up']:.2f}x)"

    assert (
        f"v0004 corrects in {said(shown['v0004'])}, trained on the 256x144 reconstructions in "
        f"{said(shown['recon256'])}, on the 512x288 ones in {said(shown['recon512'])}"
    ) in text
    paired = results("paired_saving_512_recon512.json")
    assert paired["sets"]["recon256_vs_recon512"]["files"] == [
        "bench/results/divider_carry_512_recon256.json",
        "bench/results/divider_carry_512_recon512.json",
    ]
    pooled = paired["pooled"]
    assert (
        f"faster than the one before on {pooled['faster_sites']} of the 20 (a saving in "
        f"{100 * pooled['saving_confidence']:.0f} % of the resamples)"
    ) in text


JOINT_SITES = {"default": "surface_joint_default.json", "9211": "surface_joint_9211.json"}
JOINT_POSES = {"true": "ground_truth", "SfM": "sfm"}


def test_joint_optimisation_table() -> None:
    """The joint optimisation by differentiable rendering against the vote, from `bench/surface_joint.py`: every row
    (site, poses, variant) shows its run's figures and time ratio; the text's verdict that no variant improves
    on the vote in every class is what the files say."""
    t = table("site, poses: surface", "bench/surface_joint.py")
    for name in JOINT_SITES.values():
        assert_names_source(t, name, "bench/surface_joint.py")
    shown = 0
    for label, cells in t.rows.items():
        site, poses, variant = (part.strip() for part in label.split(","))
        (run,) = [r for r in results(JOINT_SITES[site])["runs"] if r["poses"] == JOINT_POSES[poses]]
        figures_of = run["vote"] if variant == "vote" else run["variants"][variant]["figures"]
        iou = figures_of["iou"]
        assert_shows(cells[1], [figures_of["elevation_rmse_m"] * 100], label)
        assert_shows(cells[2], [iou["road"], iou["curb"], iou["lane_marking"], iou["crosswalk"]], label)
        assert_shows(cells[3], [figures_of["psnr_db"]], label)
        ratio = 1.0 if variant == "vote" else run["variants"][variant]["minus_vote"]["seconds_ratio"]
        assert_shows(cells[4], [figures_of["seconds"]["total"], ratio], label)
        shown += 1
    recorded = [
        change["minus_vote"]
        for name in JOINT_SITES.values()
        for run in results(name)["runs"]
        for change in run["variants"].values()
    ]
    assert shown == len(recorded) + sum(len(results(name)["runs"]) for name in JOINT_SITES.values())
    # "no variant raises every class's IoU without costing PSNR": each loses somewhere
    assert all(min(change["iou"].values()) < 0 or change["psnr_db"] < 0 for change in recorded)


def _sites_of(command: str, flag: str) -> set[str]:
    """The sites a recorded loop command names after `flag` (repeatable)."""
    return set(re.findall(rf"--{flag} (\S+)", command))


def _held_out_correction_s(recorded: dict[str, Any], proposer: str, sites: set[str]) -> float:
    """The total correction seconds of a `bench/vma_masks.py` run's `proposer` on the reconstructions of `sites`."""
    annotator = recorded["results"]["reconstructed"][proposer]["annotator"]
    chosen = [
        seconds
        for site, seconds in zip(annotator["sites"], annotator["per_site_correction_s"], strict=True)
        if site.split(" ")[0] in sites
    ]
    assert len(chosen) == len(sites)
    return sum(chosen)


def _check_split(run: dict[str, Any], counts: list[int], site_name: str) -> None:
    """A loop run's sites: `counts` corrected, gating and held out, every one named with `site_name`, none in two
    roles."""
    roles = [_sites_of(run["command"], flag) for flag in ("new-recon-site", "gate-recon-site", "recon-site")]
    assert [len(r) for r in roles] == counts
    assert all(site_name in site for r in roles for site in r)
    assert len(set().union(*roles)) == sum(counts)


def _without_sites(command: str) -> str:
    """A loop command without its site flags: what two splits of one experiment must share."""
    return re.sub(r"--(new-recon-site|gate-recon-site|recon-site) \S+ ?", "", command)


def test_loop_at_1024_tables() -> None:
    """The rounds at 1024x576: from v0003 on the tuning split with the mAP gate's tolerance at 0 and at 0.02 (the
    same command otherwise), on the confirmation split and with nine gate sites (the same command but the sites,
    none of them in two roles), and from the shipped v0004 without and with rehearsal; each round as both gates
    decided it, and README's scale against the shipped v0004 on the same sites."""
    runs = {
        "round, 1024x576 from v0003, mAP tolerance 0": ("vma_loop_masks_1024_v0003.json", 0.0),
        "round, 1024x576 from v0003, mAP tolerance 0.02": ("vma_loop_masks_1024_v0003_tol02.json", 0.02),
        "round, 1024x576 from v0003, confirmation split": (
            "vma_loop_masks_1024_v0003_tol02_confirm.json",
            0.02,
        ),
        "round, 1024x576 from v0003, nine gate sites": ("vma_loop_masks_1024_v0003_gate9.json", 0.02),
        "round, 1024x576 from v0003, nine gate sites, confirmation split": (
            "vma_loop_masks_1024_v0003_gate9_confirm.json",
            0.02,
        ),
        "round, 1024x576 from the shipped v0004": ("vma_loop_masks_1024_v0004.json", 0.0),
        "round, 1024x576 from the shipped v0004, rehearsing": (
            "vma_loop_masks_1024_v0004_rehearse.json",
            0.0,
        ),
    }
    recorded = {}
    for header, (name, tolerance) in runs.items():
        t = table(header, "bench/vma_loop.py")
        recorded[name] = results(name)
        assert_names_source(t, name, "bench/vma_loop.py")
        _check_confident_rounds(t, recorded[name], tolerance)
    tuning, tolerant, confirm, gate9, gate9_confirm, shipped_start, rehearsing = (
        recorded[name] for name, _ in runs.values()
    )
    assert shipped_start["command"] == tuning["command"].replace(
        "--checkpoint models/vma/element_masks/checkpoints/v0003 ",
        "--checkpoint models/vma/element_masks/checkpoints ",
    )
    assert rehearsing["command"] == shipped_start["command"].replace(
        "--replay-sites 4 --replay-share 0.0 ",
        "--replay-sites 4 --replay-reconstructions 6 --replay-share 0.5 ",
    )
    # every candidate from v0004 is slower on the gate: no mAP tolerance would promote it
    for entry in [*shipped_start["rounds"][1:], *rehearsing["rounds"][1:]]:
        gate = entry["gate"]
        assert gate["candidate"]["review"]["correction_s"] > gate["current"]["review"]["correction_s"]
    assert tuning["command"] + " " == tolerant["command"].replace("--map-tolerance 0.02 ", "") + " "
    assert "--map-tolerance" not in tuning["command"] and "--map-tolerance 0.02 " in tolerant["command"]
    assert "--checkpoint models/vma/element_masks/checkpoints/v0003 " in confirm["command"]

    assert _without_sites(confirm["command"]) == _without_sites(tolerant["command"])
    for run in (gate9, gate9_confirm):
        assert _without_sites(run["command"]) == _without_sites(tolerant["command"])
    splits = ((tolerant, [3, 5, 12]), (confirm, [3, 5, 12]), (gate9, [3, 9, 8]), (gate9_confirm, [3, 9, 8]))
    for run, counts in splits:
        _check_split(run, counts, "random1024-")
    same_model = [run["rounds"][1]["gate"]["candidate"] for run in (tuning, tolerant)]
    for key in ("mean_ap", "class_ap", "review"):  # not its timing
        assert same_model[0][key] == same_model[1][key], key
    text = " ".join(readme_text().split())
    for name, _ in runs.values():
        assert f"{results(name)['seconds']:.0f} s" in text
    shipped = results("vma_masks_resolution_1024.json")
    closed = []
    for run in (tolerant, confirm):
        held_out = _sites_of(run["command"], "recon-site")
        v0004 = _held_out_correction_s(shipped, "element_masks", held_out)
        rules = _held_out_correction_s(shipped, "rule_based", held_out)
        assert rules == pytest.approx(run["rule_based"]["reconstructed"]["annotator"]["correction_s"])
        before, after = (
            run["rounds"][k]["heldout"]["reconstructed"]["annotator"]["correction_s"] for k in (0, 1)
        )
        closed.append(f"{100 * (before - after) / (before - v0004):.0f} %")
        assert f"{v0004:.0f} s" in text and f"{after:.0f} s" in text and f"{before:.0f} s" in text
    assert f"closes {closed[0]} and {closed[1]} of that gap" in text
    for entry in gate9_confirm["rounds"][2:]:  # slower on the gate in total: no tolerance would promote them
        gate = entry["gate"]
        assert gate["candidate"]["review"]["correction_s"] > gate["current"]["review"]["correction_s"]
    speed_ups = [
        [entry["heldout"]["reconstructed"]["annotator"]["speed_up"] for entry in run["rounds"][:2]]
        for run in (tolerant, confirm, gate9, gate9_confirm)
    ]
    lifts, reached = [after - before for before, after in speed_ups], [after for _, after in speed_ups]
    assert f"by {min(lifts):.2f}-{max(lifts):.2f}x (to {min(reached):.2f}-{max(reached):.2f}x)" in text
    rising = [entry["heldout"]["reconstructed"]["annotator"] for entry in gate9["rounds"][:3]]
    assert " -> ".join(f"{a['speed_up']:.2f}x" for a in rising) in text
    assert " -> ".join(f"{a['correction_s']:.0f}" for a in rising) + " s" in text


def test_refused_round_two_candidate_at_1024() -> None:
    """The tuning run's refused round-2 candidate, scored on that run's held-out sites: its corrections are rounds 1
    and 2's, its figures and the promoted model's are as recorded, and README's reading of the gate holds."""
    refused = results("vma_masks_1024_loop_refused_v0005.json")
    loop = results("vma_loop_masks_1024_v0003_tol02.json")
    assert refused["checkpoint"]["version"] == loop["rounds"][2]["candidate"] == "v0005"
    corrected = [c["site_id"] for c in refused["checkpoint"]["data"]["corrections"]]
    assert corrected == ["random1024-9211", "random1024-9212"]
    assert _sites_of(refused["command"], "recon-site") == _sites_of(loop["command"], "recon-site")
    ours = refused["results"]["reconstructed"]["element_masks"]
    promoted = loop["rounds"][1]["heldout"]
    assert refused["results"]["reconstructed"]["rule_based"]["annotator"]["correction_s"] == pytest.approx(
        loop["rule_based"]["reconstructed"]["annotator"]["correction_s"]
    )
    gate = loop["rounds"][2]["gate"]
    saved_on_gate = gate["current"]["review"]["correction_s"] - gate["candidate"]["review"]["correction_s"]
    saved_held_out = (
        promoted["reconstructed"]["annotator"]["correction_s"] - ours["annotator"]["correction_s"]
    )
    text = " ".join(readme_text().split())
    assert (
        f"scores {ours['observed_truth']['mean_ap']:.3f} mAP and {ours['annotator']['speed_up']:.2f}x "
        f"({ours['annotator']['correction_s']:.0f} s of correction) against the promoted round-1 model's "
        f"{promoted['reconstructed']['observed_truth']['mean_ap']:.3f} and "
        f"{promoted['reconstructed']['annotator']['speed_up']:.2f}x "
        f"({promoted['reconstructed']['annotator']['correction_s']:.0f} s)"
    ) in text
    clean = refused["results"]["clean"]["element_masks"]["annotator"]["speed_up"]
    assert f"{clean:.2f}x against {promoted['annotator']['speed_up']:.2f}x on the clean BEV sites" in text
    assert (
        f"saved {saved_on_gate:.0f} s of {gate['current']['review']['correction_s']:.0f} "
        f"in {100 * gate['saving_confidence']:.0f} % of the resamples" in text
    )
    assert f"on the twelve held-out ones it saves {saved_held_out:.0f} s" in text
    share = 100 * saved_held_out / promoted["reconstructed"]["annotator"]["correction_s"]
    assert f"this refusal cost the annotator {share:.0f} %" in text
    assert f"{refused['seconds']:.0f} s)" in text


def test_loop_retrained_from_round_zero_tables() -> None:
    """The rounds at 256x144 from v0003, fine-tuning the promoted model and retraining v0003 on every correction so
    far: the same command but `--retrain-from first`, the sites in the tuning split's roles, each round as both gates
    decided it, round 1 the same model in both, and the longer trainings' slower candidates README names."""
    runs = {
        "round, 256x144 from v0003, fine-tuning the promoted model": "vma_loop_masks_tiny_v0003_promoted.json",
        "round, 256x144 from v0003, retrained from v0003": "vma_loop_masks_tiny_v0003_first.json",
    }
    for header, name in runs.items():
        t = table(header, "bench/vma_loop.py")
        assert_names_source(t, name, "bench/vma_loop.py")
        _check_confident_rounds(t, results(name), 0.02)
    fine_tuned, first = (results(name) for name in runs.values())
    assert first["command"] == fine_tuned["command"].replace(
        "--map-tolerance 0.02 ", "--map-tolerance 0.02 --retrain-from first "
    )
    _check_split(fine_tuned, [3, 5, 8], "/random-92")
    assert {r["trained_from"] for r in first["rounds"][1:]} == {"v0003"}
    assert {r["trained_from"] for r in fine_tuned["rounds"][1:]} == {"promoted"}
    same_model = [run["rounds"][1]["gate"]["candidate"] for run in (fine_tuned, first)]
    for key in ("mean_ap", "class_ap", "review"):
        assert same_model[0][key] == same_model[1][key], key
    # nothing promoted before round 3, so rounds 2 and 3 differ in their steps alone
    assert not any(r["promoted"] for r in fine_tuned["rounds"][1:3])
    text = " ".join(readme_text().split())
    for k in (2, 3):
        longer, fixed = (
            run["rounds"][k]["gate"]["candidate"]["review"]["correction_s"] for run in (first, fine_tuned)
        )
        assert longer > fixed and f"{longer:.0f} s against {fixed:.0f} s" in text
    for run in runs.values():
        assert f"{results(run)['seconds']:.0f} s)" in text
    assert all(r["retrain_seconds"] <= 20 * 60 for run in (fine_tuned, first) for r in run["rounds"][1:])


def test_loop_from_round_zero_confirmation_table() -> None:
    """The fine-tuning rounds at 256x144 on the confirmation split's roles: the tuning run's command but the sites,
    each round as both gates decided it, and the rise from round 0 to round 3 README reports."""
    name = "vma_loop_masks_tiny_v0003_promoted_confirm.json"
    t = table(
        "round, 256x144 from v0003, fine-tuning the promoted model, confirmation split", "bench/vma_loop.py"
    )
    assert_names_source(t, name, "bench/vma_loop.py")
    confirm = results(name)
    _check_confident_rounds(t, confirm, 0.02)
    _check_split(confirm, [3, 5, 12], "/random-92")
    assert _without_sites(confirm["command"]) == _without_sites(
        results("vma_loop_masks_tiny_v0003_promoted.json")["command"]
    )
    text = " ".join(readme_text().split())
    assert f"{confirm['seconds']:.0f} s;" in text
    recon = [r["heldout"]["reconstructed"] for r in confirm["rounds"]]
    for part, key in (("observed_truth", "mean_ap"), ("annotator", "speed_up")):
        curve = [r[part][key] for r in recon]
        assert curve == sorted(curve) and curve[-1] > curve[0], key  # never falls, ends above round 0
    # the promoted candidate is gated as it is stored: round 2 scores it as the current model exactly as round 1 did
    assert confirm["rounds"][1]["promoted"]
    promoted_as_candidate, as_current = (
        confirm["rounds"][1]["gate"]["candidate"],
        confirm["rounds"][2]["gate"]["current"],
    )
    for key in ("mean_ap", "class_ap", "review"):
        assert promoted_as_candidate[key] == as_current[key], key
    rules = confirm["rule_based"]["reconstructed"]["observed_truth"]["mean_ap"]
    assert f"{recon[-1]['observed_truth']['mean_ap'] - rules:.3f} mAP above the rules" in text
    # the same split retrained from v0003: the same command with --retrain-from first; its round-3 candidate
    # slower than the fine-tuned one, which was promoted
    name = "vma_loop_masks_tiny_v0003_first_confirm.json"
    t = table("round, 256x144 from v0003, retrained from v0003, confirmation split", "bench/vma_loop.py")
    assert_names_source(t, name, "bench/vma_loop.py")
    first = results(name)
    _check_confident_rounds(t, first, 0.02)
    assert first["command"] == confirm["command"].replace(
        "--map-tolerance 0.02 ", "--map-tolerance 0.02 --retrain-from first "
    )
    assert f"{first['seconds']:.0f} s;" in text
    gate = first["rounds"][3]["gate"]
    assert not first["rounds"][3]["promoted"] and confirm["rounds"][3]["promoted"]
    assert (
        gate["candidate"]["review"]["correction_s"]
        >= confirm["rounds"][3]["gate"]["candidate"]["review"]["correction_s"]
    )
    assert f"{gate['current']['mean_ap'] - gate['candidate']['mean_ap']:.3f} lower in mAP" in text


KERB_BINS = (-0.2, -0.1, 0.1, 0.2, 0.3, 0.4)
"""The bins of the kerb profile table, by their lower end (m from the true road edge)."""


def _profile_row(run: dict[str, Any], pick: Any) -> list[Expected]:
    by_start = {b["from_m"]: b for b in run["bins"]}
    return [pick(by_start[start]) for start in KERB_BINS]


def test_kerb_profile_table() -> None:
    t = table("across the kerb, default site, SfM poses", "bench/kerb_profile.py")
    assert t.header[1:7] == [f"{start:+.1f} m".replace("+-", "-") for start in KERB_BINS]
    off, foot, line = (
        results(f"kerb_profile{suffix}.json")["runs"]["sfm"] for suffix in ("", "_foot", "_line")
    )
    for name in ("kerb_profile.json", "kerb_profile_foot.json", "kerb_profile_line.json"):
        assert_names_source(t, name, "bench/kerb_profile.py")
    assert (off["kerb_line"], off["kerb_band_m"]) == (False, 0.0)
    assert (foot["kerb_line"], foot["kerb_band_m"]) == (False, 0.3)
    assert (line["kerb_line"], line["kerb_band_m"]) == (True, 0.0)
    rows: dict[str, list[Expected]] = {
        "true curb share": _profile_row(off, lambda b: b["true_curb_share"]),
        "road-level vote: road share": _profile_row(off, lambda b: b["road_level_shares"]["road"]),
        "curb-height vote: road share": _profile_row(off, lambda b: b["curb_height_shares"]["road"]),
        "labelled right: without the kerb line": [
            *_profile_row(off, lambda b: b["right"]),
            off["iou"]["curb"],
        ],
        "labelled right: kerb foot (0.3 m), without the kerb line": [
            *_profile_row(foot, lambda b: b["right"]),
            foot["iou"]["curb"],
        ],
        "labelled right: the kerb line": [*_profile_row(line, lambda b: b["right"]), line["iou"]["curb"]],
        "labelled right: each cell read at its true height": [
            *_profile_row(off, lambda b: b["right_at_true_height"]),
            off["band_iou"]["at_true_height"]["curb"],
        ],
    }
    for label, expected in rows.items():
        assert_shows(" | ".join(row(t, label)[1:]), expected, f"kerb profile row {label!r}")
    # the votes are the same in the three runs: only the decision of heights differs
    assert _profile_row(foot, lambda b: b["road_level_shares"]["road"]) == rows["road-level vote: road share"]
    assert (
        _profile_row(line, lambda b: b["curb_height_shares"]["road"]) == rows["curb-height vote: road share"]
    )


def test_kerb_profile_masks_table() -> None:
    t = table("across the kerb, default twin, SfM poses, own frame", "bench/kerb_profile.py")
    assert t.header[1:7] == [f"{start:+.1f} m".replace("+-", "-") for start in KERB_BINS]
    runs = {}
    for masks, name in (("segmenter", "predicted"), ("generator", "generator")):
        assert_names_source(t, f"kerb_profile_twin_own_{masks}.json", "bench/kerb_profile.py")
        run = results(f"kerb_profile_twin_own_{masks}.json")["runs"]["sfm"]
        assert (run["masks"], run["frame"]) == (name, "own"), masks
        runs[masks] = run
    rows: dict[str, list[Expected]] = {
        "true curb share": _profile_row(runs["segmenter"], lambda b: b["true_curb_share"])
    }
    for masks, run in runs.items():
        rows[f"curb-height vote: curb share, {masks}'s masks"] = _profile_row(
            run, lambda b: b["curb_height_shares"]["curb"]
        )
        rows[f"labelled right, {masks}'s masks"] = [
            *_profile_row(run, lambda b: b["right"]),
            run["iou"]["curb"],
        ]
        rows[f"read at its true height, {masks}'s masks"] = [
            *_profile_row(run, lambda b: b["right_at_true_height"]),
            run["band_iou"]["at_true_height"]["curb"],
        ]
    for label, expected in rows.items():
        assert_shows(" | ".join(row(t, label)[1:]), expected, f"kerb profile by masks, row {label!r}")
    # README's reading: the segmenter's masks lose most at the kerb's outer edge (the bin from 0.3 m)
    right = {masks: {b["from_m"]: b["right"] for b in run["bins"]} for masks, run in runs.items()}
    losses = {start: right["generator"][start] - right["segmenter"][start] for start in KERB_BINS}
    assert max(losses, key=lambda start: losses[start]) == 0.3


def _check_annotator_column(t: MarkdownTable, run: dict[str, Any], column: str) -> None:
    """One column of the annotator-by-masks table: each class's seconds and its accepted / fixed / rejected /
    drawn counts, the road scan, and correction against drawing."""
    index = t.header.index(column)
    for label, name in (("crossings", "ped_crossing"), ("dividers", "divider"), ("boundaries", "boundary")):
        booked = run["booked"][name]
        counts = [booked.get(action, {}).get("count", 0) for action in ("accept", "fix", "reject", "drawn")]
        seconds = sum(action["seconds"] for action in booked.values())
        assert_shows(row(t, label)[index], [seconds, *counts], f"annotator by masks, {column}, {label}")
    assert_shows(row(t, "road scan")[index], [run["booked"]["road"]["scan"]["seconds"]], column)
    totals = [run["correction_s"], run["drawing_s"], run["drawing_s"] / run["correction_s"]]
    assert_shows(row(t, "correction against drawing")[index], totals, column)


def test_annotator_seconds_by_masks_table() -> None:
    t = table(
        "annotator's seconds on the default twin, v0004 proposing: class, accepted / fixed / rejected / drawn"
    )
    assert_names_source(t, "annotator_seconds_twin_masks.json", "bench/annotator_seconds.py")
    per_site = results("annotator_seconds_twin_masks.json")["per_site"]
    by_masks = {run["site"].rsplit("twin-", 1)[1]: run for run in per_site}
    for masks in ("segmenter", "generator"):
        _check_annotator_column(t, by_masks[masks], f"{masks}'s masks")
    # README's reading: the boundaries cost the same through either masks, the crossings do not
    boundary = {
        m: sum(a["seconds"] for a in run["booked"]["boundary"].values()) for m, run in by_masks.items()
    }
    assert round(boundary["segmenter"], 1) == round(boundary["generator"], 1)
    # the mirror-averaged masks' column, from a run that repeats the plain masks' site to the tenth of a second
    assert_names_source(t, "annotator_seconds_twin_mirrored.json", "bench/annotator_seconds.py")
    mirrored_runs = {
        run["site"].rsplit("twin-", 1)[1]: run
        for run in results("annotator_seconds_twin_mirrored.json")["per_site"]
    }
    assert round(mirrored_runs["segmenter"]["correction_s"], 1) == round(
        by_masks["segmenter"]["correction_s"], 1
    )
    _check_annotator_column(t, mirrored_runs["flip"], "segmenter's masks, mirror averaged")


def test_surface_through_mirrored_masks_table() -> None:
    t = table("the default twin's surface, SfM poses, through", "The surface under those proposals")
    assert_names_source(t, "surface_twin_mirrored.json", "bench/surface_variants.py")
    sites = results("surface_twin_mirrored.json")["sites"]
    for label, suffix in (
        ("the segmenter's masks", "/default-nomasks"),
        ("the segmenter's masks, mirror averaged", "/twin-flip"),
    ):
        (site,) = [figures for path, figures in sites.items() if path.endswith(suffix)]
        run = site["runs"]["shipped"]
        own = run["iou_in_reconstruction_frame"]
        cells = row(t, label)
        assert_shows(cells[1], [run["elevation_rmse_cm"]], label)
        assert_shows(cells[2], [own[c] for c in ("road", "curb", "lane_marking", "crosswalk")], label)
        assert_shows(cells[3], [run["psnr_db"]], label)


KERB_LINE_ROWS = {
    "without the kerb line": ("sfm", False, 0.0),
    "kerb foot": ("variant_kerb_foot", False, 0.3),
    "kerb line": ("variant_kerb_line_toggled", True, 0.0),
}


KERB_LINE_DEFAULT_ROWS = {
    "without the kerb line": ("variant_kerb_line_toggled", False, 0.0),
    "kerb line": ("sfm", True, 0.0),
}
"""The rows of a site measured with the kerb line on by default (its toggled run is the one without)."""


def test_kerb_line_surface_table() -> None:
    t = table("kerb cells, SfM poses", "bench/surface.py")
    for site, results_file, rows in (
        ("default site", "surface_kerb_line.json", KERB_LINE_ROWS),
        ("9011", "surface_kerb_line_9011.json", KERB_LINE_ROWS),
        ("9011 mask-free", "surface_kerb_line_9011_nomasks.json", KERB_LINE_DEFAULT_ROWS),
    ):
        assert_names_source(t, results_file, "bench/surface.py")
        recorded = results(results_file)
        for variant, (key, kerb_line, band) in rows.items():
            run = _surface_run(recorded, key)
            assert (run["poses"], run["kerb_line"], run["kerb_band_m"]) == ("sfm", kerb_line, band)
            assert run["masks"] == ("predicted" if "mask-free" in site else "dataset")
            label = f"{site}, {variant}"
            assert_shows(" | ".join(row(t, label)[1:]), _surface_figures(run), f"kerb line row {label!r}")


def test_kerb_line_end_to_end_table() -> None:
    t = table("end to end, kerb line", "bench/end_to_end.py")
    for site, suffix in (("default site", ""), ("9011", "_9011"), ("9011 mask-free", "_9011_nomasks")):
        for state in ("off", "on"):
            results_file = f"end_to_end_kerb_line_{state}{suffix}.json"
            assert_names_source(t, results_file, "bench/end_to_end.py")
            recorded = results(results_file)
            observed, annotator = recorded["proposals_ap"]["observed_truth"], recorded["annotator"]
            counts = annotator["corrected"]["counts"]
            expected: list[Expected] = [
                observed["mean_ap"],
                observed["class_ap"]["boundary"],
                annotator["speed_up"],
                recorded["annotator_in_reconstruction_frame"]["speed_up"],
                *(counts.get(kind, 0) for kind in ("accept", "fix", "reject", "drawn")),
                recorded["sre"]["c1_proposals"]["sre_ref_px"],
            ]
            assert_shows(" | ".join(row(t, f"{site}, {state}")[1:]), expected, f"end to end {site} {state}")
    # the same drawing in both runs of a site: only the proposals differ
    for suffix in ("", "_9011", "_9011_nomasks"):
        off, on = (results(f"end_to_end_kerb_line_{s}{suffix}.json")["annotator"] for s in ("off", "on"))
        assert off["scratch"]["total_s"] == on["scratch"]["total_s"]


def test_kerb_line_twenty_layouts_table() -> None:
    t = table("twenty held-out layouts at 256x144, kerb line", "bench/vma_masks.py")
    commands = {}
    for state in ("off", "on"):
        results_file = f"vma_masks_kerb_line_{state}_256.json"
        assert_names_source(t, results_file, "bench/vma_masks.py")
        recorded = results(results_file)
        commands[state] = recorded["command"]
        network, rules = (
            recorded["results"]["reconstructed"][name] for name in ("element_masks", "rule_based")
        )
        expected: list[Expected] = [
            network["observed_truth"]["mean_ap"],
            network["observed_truth"]["class_ap"]["divider"],
            network["observed_truth"]["class_ap"]["boundary"],
            network["annotator"]["correction_s"],
            network["annotator"]["speed_up"],
            rules["observed_truth"]["mean_ap"],
            rules["annotator"]["speed_up"],
        ]
        assert_shows(" | ".join(row(t, state)[1:]), expected, f"twenty layouts, kerb line {state}")
    # the same twenty layouts, the copies rerun with the kerb line
    sites = {
        state: re.findall(r"--recon-site data/synthetic/(\S+)", command)
        for state, command in commands.items()
    }
    assert sites["off"] == [f"random-{seed}" for seed in range(9211, 9231)]
    assert sites["on"] == [f"line-{seed}" for seed in range(9211, 9231)]


def test_kerb_line_trained_network_table() -> None:
    """v0004 and its recipe retrained on the twelve reconstructions with and without the kerb line, each cell
    against its bench/vma_masks.py results, on the twenty layouts with the kerb line; the halves add up."""
    t = table("network, twenty held-out layouts with the kerb line", "bench/vma_masks.py")
    rows = {
        "v0004 (shipped)": "vma_masks_kerb_line_on_256_rerun.json",
        "v0004's recipe on rasters without the kerb line": "vma_masks_kerb_line_trained_off_256.json",
        "v0004's recipe on rasters with the kerb line": "vma_masks_kerb_line_trained_on_256.json",
    }
    trained_on = {}
    for label, results_file in rows.items():
        assert_names_source(t, results_file, "bench/vma_masks.py")
        recorded = results(results_file)
        assert re.findall(r"--recon-site data/synthetic/(\S+)", recorded["command"]) == [
            f"line-{seed}" for seed in range(9211, 9231)
        ]
        network = _recon_masks(recorded)
        observed, annotator = network["observed_truth"], network["annotator"]
        halves = [sum(annotator["per_site_correction_s"][:10]), sum(annotator["per_site_correction_s"][10:])]
        clean = recorded["results"]["clean"]["element_masks"]
        expected: list[Expected] = [
            observed["mean_ap"],
            *(observed["class_ap"][c] for c in ("divider", "ped_crossing", "boundary")),
            annotator["correction_s"],
            *halves,
            annotator["speed_up"],
            clean["mean_ap"],
            clean["annotator"]["speed_up"],
        ]
        assert_shows(" | ".join(row(t, label)[1:]), expected, label)
        trained_on[label] = recorded["checkpoint"]["data"]["reconstructions"]
    assert all("/off-91" in path for path in trained_on["v0004's recipe on rasters without the kerb line"])
    assert all("/random-91" in path for path in trained_on["v0004's recipe on rasters with the kerb line"])
    # the rerun of v0004 is the run the kerb line's table shows, figure for figure
    rerun, before = (
        results(name)["results"]
        for name in ("vma_masks_kerb_line_on_256_rerun.json", "vma_masks_kerb_line_on_256.json")
    )
    assert rerun["reconstructed"] == before["reconstructed"]


def test_annotator_seconds_table() -> None:
    """Each cell of the annotator's seconds against bench/annotator_seconds.py's results, and the sums and
    ceilings the paragraph below it gives."""
    t = table("annotator's seconds, twenty layouts, v0004", "bench/annotator_seconds.py")
    assert_names_source(t, "annotator_seconds_256.json", "bench/annotator_seconds.py")
    recorded = results("annotator_seconds_256.json")
    assert len(recorded["per_site"]) == 20
    booked = recorded["booked"]
    actions = {
        "accepted": "accept",
        "fixed": "fix",
        "rejected": "reject",
        "drawn, no proposal covered it": "drawn",
    }
    for label, action in actions.items():
        expected: list[Expected] = []
        for cls in ("divider", "ped_crossing", "boundary"):
            entry = booked[cls][action]
            expected += [entry["seconds"], entry["count"]]
        assert_shows(" | ".join(row(t, label)[1:]), expected, label)
    text = readme_text()
    scan = booked["road"]["scan"]["seconds"]
    assert (
        f"With the road scan ({scan:.0f} s) that is the {recorded['correction_s']:,.0f} s of correction"
        in text
    )
    assert f"against {recorded['drawing_s']:,.0f} s of drawing ({recorded['speed_up']:.2f}x)" in text
    ceilings = recorded["ceilings"]
    assert f"the speed-up would be {ceilings['fixes_within_chamfer_accepted']['speed_up']:.2f}x" in text
    assert (
        f"With nothing left to draw it would be {ceilings['nothing_left_to_draw']['speed_up']:.2f}x" in text
    )
    at_end = [
        entry
        for cls in ("divider", "boundary")
        for reason, entry in recorded["fix_reasons"][cls].items()
        if "at the end vertex" in reason
    ]
    within = [
        entry
        for cls in ("divider", "boundary")
        for reason, entry in recorded["fix_reasons"][cls].items()
        if reason.startswith("within")
    ]
    line_fixes = [booked[cls]["fix"] for cls in ("divider", "boundary")]
    assert (
        f"{sum(e['count'] for e in at_end)} of the {sum(e['count'] for e in line_fixes)} line fixes "
        f"({sum(e['seconds'] for e in at_end):.0f} of their {sum(e['seconds'] for e in line_fixes):.0f} s)"
    ) in text
    assert f"{sum(e['count'] for e in within)} of those ({sum(e['seconds'] for e in within):.0f} s)" in text


def test_kerb_count_at_step_height_figures() -> None:
    """The curb IoU and confusion the paragraph on counting step cells at curb height gives, from its files."""
    text = readme_text()
    for name in (
        "kerb_profile_count_at_step.json",
        "kerb_profile_count_at_step_9011.json",
        "kerb_profile_line_9011.json",
        "kerb_profile_line.json",
    ):
        assert f"bench/results/{name}" in text
    sfm = {
        name: results(f"kerb_profile_{name}.json")["runs"]["sfm"]
        for name in ("line", "count_at_step", "line_9011", "count_at_step_9011")
    }
    iou = {name: run["iou"]["curb"] for name, run in sfm.items()}
    assert f"default site ({iou['line']:.3f} -> {iou['count_at_step']:.3f} against" in text
    assert f"on 9011 ({iou['line_9011']:.3f} -> {iou['count_at_step_9011']:.3f})" in text
    background = {
        name: sfm[name]["curb_confusion"]["true_curb_labelled_background"]
        for name in ("line", "count_at_step")
    }
    assert (
        f"background {background['line']:.3f} -> {background['count_at_step']:.3f} on the default site"
        in text
    )
    # the baseline on 9011 is the code as it is, with the kerb line
    assert sfm["line_9011"]["kerb_line"] and sfm["count_at_step_9011"]["kerb_line"]


TRUTH_GRID_SITES = {
    "default site": ("surface_kerb_line.json", "surface_truth_grid_default.json"),
    "9011": ("surface_kerb_line_9011.json", "surface_truth_grid_9011.json"),
    "9011 mask-free": ("surface_kerb_line_9011_nomasks.json", "surface_truth_grid_9011_nomasks.json"),
}
"""Per site of the truth-grid table: the nearest-cell results (the kerb line's table) and the own-grid ones."""


def _class_figures(scored: dict[str, Any]) -> list[Expected]:
    iou = scored["iou"]
    return [iou["road"], iou["curb"], iou["lane_marking"], iou["crosswalk"], scored["psnr_db"]]


def test_truth_grid_table() -> None:
    t = table("surface with the kerb line, scored against", "truth_grid")
    for site, (nearest_file, own_file) in TRUTH_GRID_SITES.items():
        for results_file in (nearest_file, own_file):
            assert_names_source(t, results_file, "bench/surface.py")
        nearest = next(
            run
            for run in (*results(nearest_file)["runs"], results(nearest_file)["variant_kerb_line_toggled"])
            if run["poses"] == "sfm" and run["kerb_line"]
        )
        own = {run["poses"]: run for run in results(own_file)["runs"]}
        assert own["sfm"]["kerb_line"] and own["ground_truth"]["kerb_line"]
        for label, run in (
            (f"{site}, SfM, nearest stored cell", nearest),
            (f"{site}, SfM, own grid", own["sfm"]),
        ):
            cells = row(t, label)
            assert_shows(cells[1], [run["elevation_rmse_m"] * 100], label)
            assert_shows(" | ".join(cells[2:]), _class_figures(run), label)
        framed = own["sfm"]["in_reconstruction_frame"]
        label, cells = row_starting(t, f"{site}, SfM, reconstruction's frame")
        assert_shows(label.removeprefix(site), [framed["frame"]["shift_cm"]], label)
        assert cells[1] == "-"
        assert_shows(" | ".join(cells[2:]), _class_figures(framed), label)
        label = f"{site}, true poses, own grid"
        if label in t.rows:
            truth_run = own["ground_truth"]
            assert_shows(row(t, label)[1], [truth_run["elevation_rmse_m"] * 100], label)
            assert_shows(" | ".join(row(t, label)[2:]), _class_figures(truth_run), label)


def test_segment_bev_iou_in_own_frame_table() -> None:
    t = table("BEV IoU road / curb / lane marking / crosswalk, site (frame shift)")
    classes = ("road", "curb", "lane_marking", "crosswalk")
    for seed in (9004, 9005, 9006):
        results_file = f"segment_truth_grid_{seed}.json"
        assert_names_source(t, results_file, "bench/segment.py")
        for masks, key in (("generator masks", "generator_masks"), ("predicted masks", "predicted_masks")):
            run = results(results_file)["runs"][key]
            label, cells = next((k, v) for k, v in t.rows.items() if k.startswith(f"{seed} (") and masks in k)
            assert_shows(label.removeprefix(str(seed)), [run["reconstruction_frame"]["shift_cm"]], label)
            assert_shows(cells[1], [run["bev_iou"][c] for c in classes], label)
            assert_shows(cells[2], [run["bev_iou_in_reconstruction_frame"][c] for c in classes], label)
            speed_ups = [run["annotator_speed_up"], run["annotator_speed_up_in_reconstruction_frame"]]
            assert_shows(cells[3], speed_ups, label)


EGO_SITES = {
    "default site": "surface_ego_default.json",
    "9011": "surface_ego_9011.json",
    "9011 mask-free": "surface_ego_9011_nomasks.json",
}
"""Per site of the ego-frame table: its results file (`bench/surface.py`'s `in_ego_frames`)."""


def test_surface_in_ego_frames_table() -> None:
    t = table("surface, in each key frame's ego frame")
    thin = ("curb", "lane_marking", "crosswalk")
    for site, results_file in EGO_SITES.items():
        assert_names_source(t, results_file, "bench/surface.py")
        for poses, shown in (("sfm", "SfM"), ("ground_truth", "true poses")):
            run = next(r for r in results(results_file)["runs"] if r["poses"] == poses)
            assert run["kerb_line"]
            ego, label = run["in_ego_frames"], f"{site}, {shown}"
            cells = row(t, label)
            road, kerbs = ego["heights_road"], ego["heights_road_and_curb"]
            global_road = road["same_pairs_in_global_frame"]["rmse_cm"]
            assert_shows(cells[1], [road["rmse_cm"], global_road, run["elevation_rmse_m"] * 100], label)
            assert_shows(cells[2], [kerbs["rmse_cm"], kerbs["same_pairs_in_global_frame"]["rmse_cm"]], label)
            assert_shows(cells[3], [ego["iou"]["ego"][c] for c in thin], label)
            assert_shows(cells[4], [ego["iou"]["same_pairs_in_global_frame"][c] for c in thin], label)
            assert_shows(cells[5], [run["iou"][c] for c in thin], label)


def test_surface_parts_in_ego_frames_table() -> None:
    t = table("SfM poses, in each key frame's ego frame")
    for site, results_file in EGO_SITES.items():
        assert_names_source(t, results_file, "bench/surface.py")
        recorded = results(results_file)
        runs = {
            "the stage": next(r for r in recorded["runs"] if r["poses"] == "sfm"),
            "vote alone (no refinement)": next(r for r in recorded["vote_runs"] if r["poses"] == "sfm"),
            "flat (no kerb step)": recorded["ablation_no_kerb_step"],
        }
        assert (
            not runs["vote alone (no refinement)"]["refine"] and not runs["flat (no kerb step)"]["kerb_step"]
        )
        for shown, run in runs.items():
            assert run["poses"] == "sfm"
            ego, label = run["in_ego_frames"], f"{site}, {shown}"
            cells = row(t, label)
            heights = [ego["heights_road"]["rmse_cm"], ego["heights_road_and_curb"]["rmse_cm"]]
            assert_shows(cells[1], heights, label)
            assert_shows(
                cells[2], [ego["iou"]["ego"][c] for c in ("curb", "lane_marking", "crosswalk")], label
            )


LOADER_ROWS = {
    "the loader before (c7b9d61), every scene": "baseline_loader",
    "`json.load` of the seven tables alone": "whole_parse",
    "every scene": "all_scenes",
    "one scene": "scenes_1",
    "ten scenes (a site)": "scenes_10",
}


def test_loader_by_scene_table() -> None:
    t = table("load, trainval-sized tables")
    assert_names_source(t, "loader_trainval.json", "bench/loader.py")
    recorded = results("loader_trainval.json")
    assert recorded["ratios_vs"] == "baseline_loader" and recorded["tables"]["scenes"] == 850
    for label, key in LOADER_ROWS.items():
        run = recorded["runs"][key]
        expected = [
            run["seconds"],
            recorded["seconds_ratio"][key],
            run["peak_rss_mb"],
            run["rss_anon_mb"],
            run["images"],
        ]
        cells = row(t, label)[1:]
        for cell, value in zip(cells, expected, strict=True):
            assert_shows(cell, [] if value is None else [value], f"loader table, {label}")


def test_wigo_flat_height_table() -> None:
    t = table("clip", "Logged poses without heights")
    files = {"default": "wigo_flat_height.json", "9011": "wigo_flat_height_9011.json"}
    for site, name in files.items():
        assert_names_source(t, name, "bench/wigo_flat_height.py")
        for scene, clip in results(name)["clips"].items():
            if clip["true_height_range_m"] < 0.1:
                continue  # standing clips are not shown
            label, cells = row_starting(t, f"{site}, {scene} ")
            assert_shows(label.split("climbs")[1], [clip["true_height_range_m"]], f"wigo flat height {label}")
            for cell, variant in zip(cells[1:], ("logged_3d", "flat_fused", "flat_free"), strict=True):
                shown = clip[variant]
                expected = [shown["vertical_rmse_m"] * 100, shown["vertical_max_m"] * 100]
                assert_shows(cell, expected, f"wigo flat height {label} {variant}")


def test_logged_height_whole_path_table() -> None:
    t = table("whole path, site and logged poses", "2D logged poses")
    files = {
        "default": "logged_height.json",
        "9011": "logged_height_9011.json",
        "hilly": "logged_height_hilly.json",
    }
    rows = [
        (site, name, key, label)
        for site, name in files.items()
        for key, label in (("logged_height", "logged heights"), ("no_logged_height", "z = 0"))
    ]
    after_only = ("hilly", "logged_height_hilly_after_only.json", "no_logged_height")
    rows.append((*after_only, "z = 0, tied after the alignment only"))
    gated = {"default": "logged_height_gate.json", "hilly": "logged_height_hilly_gate.json"}
    for site, name in gated.items():
        for key, label in (("logged_height", "logged heights"), ("no_logged_height", "z = 0")):
            rows.append((site, name, key, f"{label}, SfM gate 1 m over 4 rounds"))
    for site, name, key, label in rows:
        assert_names_source(t, name, "bench/logged_height.py")
        run = results(name)["runs"][key]
        heights, bev = run["clip_heights"], run["bev_iou_in_reconstruction_frame"]
        expected: list[list[Expected]] = [
            [run["poses"]["sfm"]["gauge_free_position_cm"]],
            [heights["wigo"]["offset_spread_cm"], heights["sfm"]["offset_spread_cm"]],
            [run["elevation_relative"]["rmse_about_offset_cm"]],
            [run["elevation_relative"]["offset_cm"]],
            [run["proposals_ap"]["observed_truth"]["mean_ap"]],
            [run["sre"]["sre_ref_px"]],
            [run["annotator_speed_up_in_reconstruction_frame"]],
            [bev[c] for c in ("road", "curb", "lane_marking", "crosswalk")],
        ]
        for cell, values in zip(row(t, f"{site}, {label}")[1:], expected, strict=True):
            assert_shows(cell, values, f"logged height table, {site}, {label}")


def test_without_wheels_table() -> None:
    t = table("whole path, site and scene-0001's wheels", "Scenes without wheel speeds")
    for site in ("9004", "9005"):
        name = f"without_wheels_{site}.json"
        assert_names_source(t, name, "bench/without_wheels.py")
        for key in ("with_wheels", "without_wheels"):
            run = results(name)["runs"][key]
            scene, bev = run["scene_poses"], run["bev_iou_in_reconstruction_frame"]
            expected: list[list[Expected]] = [
                [scene["wigo"]["position_cm"], scene["wigo"]["rotation_deg"]],
                [scene["sfm"]["position_cm"], scene["sfm"]["rotation_deg"]],
                [run["poses"]["sfm"]["gauge_free_position_cm"]],
                [run["elevation"]["rmse_cm"]],
                [run["proposals_ap"]["observed_truth"]["mean_ap"]],
                [run["sre"]["sre_ref_px"]],
                [run["annotator_speed_up_in_reconstruction_frame"]],
                [bev[c] for c in ("road", "curb", "lane_marking", "crosswalk")],
            ]
            label = f"{site}, {key.replace('_', ' ')}"
            for cell, values in zip(row(t, label)[1:], expected, strict=True):
                assert_shows(cell, values, f"without wheels table, {label}")


def test_unjoined_clips_table() -> None:
    t = table("default site, z = 0, clips", "Clips no point joins")
    assert_names_source(t, "unjoined_clips.json", "bench/unjoined_clips.py")
    labels = {
        "joined": "joined by their points",
        "unjoined_tied": "no shared point, heights tied",
        "unjoined_untied": "no shared point, untied",
    }
    for key, prefix in labels.items():
        run = results("unjoined_clips.json")["runs"][key]
        bev = run["bev_iou_in_reconstruction_frame"]
        expected: list[list[Expected]] = [
            [run["poses"]["sfm"]["gauge_free_position_cm"]],
            [run["clip_heights"]["sfm"]["offset_spread_cm"]],
            [run["elevation_relative"]["rmse_about_offset_cm"]],
            [run["proposals_ap"]["observed_truth"]["mean_ap"]],
            [run["sre"]["sre_ref_px"]],
            [run["annotator_speed_up_in_reconstruction_frame"]],
            [bev[c] for c in ("road", "curb", "lane_marking", "crosswalk")],
        ]
        label, cells = row_starting(t, prefix)
        for cell, values in zip(cells[1:], expected, strict=True):
            assert_shows(cell, values, f"unjoined clips table, {label}")


def test_export_trainval_table() -> None:
    t = table("nuScenes-CAMAv2 export, trainval-sized tables, a site of ten scenes")
    assert_names_source(t, "export_trainval.json", "bench/export_trainval.py")
    runs = results("export_trainval.json")["runs"]
    labels = {
        "baseline_export_site": "the export before (996cc4f)",
        "export_site": "the export now",
        "whole_parse": "`json.load` of the six tables it reads, alone",
        "load_site": "loading the site's ten scenes, alone",
    }
    for key, label in labels.items():
        run = runs[key]
        for cell, value in zip(row(t, label)[1:], (run["seconds"], run["peak_rss_mb"]), strict=True):
            assert_shows(cell, [value], f"export trainval table, {label}")
    ratio = runs["baseline_export_site"]["seconds"] / runs["export_site"]["seconds"]
    assert_shows(row(t, "the export now")[1].split("(")[1], [ratio], "export trainval speed-up")


def test_surface_gate_table() -> None:
    t = table("SfM gate, SfM poses", "The road's height past a grade change")
    assert_names_source(t, "surface_gate.json", "bench/surface_gate.py")
    sites = results("surface_gate.json")["sites"]
    hilly, default = (sites[name] for name in sorted(sites, key=lambda name: "default" in name))
    for label in hilly["runs"]:
        cells = row(t, label)[1:]
        for i, site in enumerate((hilly, default)):
            figures = site["runs"][label]
            bands = figures["elevation_rmse_cm_by_distance_m"]
            expected = [figures["elevation_rmse_cm"], bands["10-14"], bands["14-100"]]
            assert_shows(cells[2 * i], expected, f"surface gate table, {label}")
            own = figures["iou_in_reconstruction_frame"]
            classes = [own[c] for c in ("road", "curb", "lane_marking", "crosswalk")]
            assert_shows(cells[2 * i + 1], classes, f"surface gate table, {label}")
        seconds = [hilly["runs"][label]["seconds"], default["runs"][label]["seconds"]]
        assert_shows(cells[4], seconds, f"surface gate table, {label}")


def test_segmenter_on_the_hill_table() -> None:
    _check_segmenter_columns(
        "class, the twins' images",
        {
            "default twin": ("segment_default_twin.json", "gpu-long2"),
            "hilly twin": ("segment_hilly.json", "gpu-long2"),
        },
    )


SURFACE_SITES = {"hilly twin": "hilly-nomasks", "default twin": "default-nomasks"} | {
    seed: f"random512-{seed}-nomasks" for seed in ("9301", "9302", "9303")
}
"""The surface tables' five columns: the two mask-free twins and the fresh 512x288 layouts, by site folder name."""


def _check_variant_columns(t: MarkdownTable, sites: dict[str, Any], where: str) -> None:
    """A `bench/surface_variants.py` table over the two twins and the layouts 9301-9303: a row per variant, each
    cell the road's elevation RMSE and the own-frame curb / lane marking / crosswalk IoU."""
    for column, name in SURFACE_SITES.items():
        (site,) = [figures for path, figures in sites.items() if path.endswith("/" + name)]
        index = t.header.index(column)
        for label, run in site["runs"].items():
            own = run["iou_in_reconstruction_frame"]
            expected = [run["elevation_rmse_cm"], own["curb"], own["lane_marking"], own["crosswalk"]]
            assert_shows(row(t, label)[index], expected, f"{where}, {label}, {column}")


def test_refinement_smoothness_table() -> None:
    t = table("refinement's smoothness, SfM poses", "How stiff the refinement is")
    assert_names_source(t, "surface_refine_smoothness.json", "bench/surface_variants.py")
    _check_variant_columns(
        t, results("surface_refine_smoothness.json")["sites"], "refinement smoothness table"
    )


def test_refinement_smoothness_end_to_end_table() -> None:
    t = table("whole path, smoothness 1 / 30", "End to end, with the element-mask network v0004")
    twins = {
        "default twin": ("logged_height_gate.json", "logged_height_smooth.json"),
        "hilly twin": ("logged_height_hilly_gate.json", "logged_height_hilly_smooth.json"),
    }
    for twin, files in twins.items():
        for suffix, run_name in ((", logged heights", "logged_height"), (", z = 0", "no_logged_height")):
            cells = row(t, twin + suffix)
            runs = [results(name)["runs"][run_name] for name in files]
            for name in files:
                assert_names_source(t, name, "bench/logged_height.py")
            maps = [run["proposals_ap"]["observed_truth"]["mean_ap"] for run in runs]
            assert_shows(cells[1], maps, f"smoothness end to end, {twin}{suffix}")
            speed_ups = [run["annotator_speed_up_in_reconstruction_frame"] for run in runs]
            assert_shows(cells[2], speed_ups, f"smoothness end to end, {twin}{suffix}")
    for seed in ("9301", "9302", "9303"):
        files = (f"end_to_end_smooth1_{seed}.json", f"end_to_end_smooth30_{seed}.json")
        runs = [results(name) for name in files]
        for name in files:
            assert_names_source(t, name, "bench/end_to_end.py")
        cells = row(t, seed)
        assert_shows(cells[1], [r["proposals_ap"]["observed_truth"]["mean_ap"] for r in runs], seed)
        assert_shows(cells[2], [r["annotator_in_reconstruction_frame"]["speed_up"] for r in runs], seed)


def test_refinement_ridge_table() -> None:
    t = table("refinement's ridge, SfM poses, smoothness 30", "ridge that holds the residual")
    sites: dict[str, Any] = {}
    for name in ("surface_refine_ridge_a.json", "surface_refine_ridge_b.json"):
        assert_names_source(t, name, "bench/surface_variants.py")
        sites |= results(name)["sites"]
    _check_variant_columns(t, sites, "refinement ridge table")


def test_masks_split_table() -> None:
    t = table(
        "the masks the surface observes through, SfM poses", "What the segmenter's masks cost the surface"
    )
    assert_names_source(t, "surface_masks_split.json", "bench/surface_variants.py")
    sites = results("surface_masks_split.json")["sites"]
    assert all(site["runs"]["generator masks"]["masks"] == "generator" for site in sites.values())
    _check_variant_columns(t, sites, "masks split table")


def test_segmenter_calibration_on_fresh_sites_table() -> None:
    """`gpu-long2` against its calibration on seven sites neither saw; the calibrated runs are of the checkpoint
    whose record the results keep."""
    columns = {
        "default twin gpu-long2": ("segment_default_twin.json", "gpu-long2"),
        "default twin calibrated": ("segment_calibrated_default_twin.json", "gpu-long2-cal184"),
        "hilly twin gpu-long2": ("segment_hilly.json", "gpu-long2"),
        "hilly twin calibrated": ("segment_calibrated_hilly.json", "gpu-long2-cal184"),
    }
    for seed in ("9301", "9302", "9303", "9004", "9005"):
        columns[f"{seed} gpu-long2"] = (f"segment_gpu_long2_{seed}.json", "gpu-long2")
        columns[f"{seed} calibrated"] = (f"segment_calibrated_{seed}.json", "gpu-long2-cal184")
    _check_segmenter_columns("class, calibrated on fresh 512x288 sites", columns)
    record = results("segmenter_calibration_cal184.json")["checkpoints"]["gpu-long2-cal184"]
    shipped = json.loads((ROOT / "cama_pipeline/segment/shipped/checkpoint.json").read_text(encoding="utf-8"))
    assert record["calibration"]["parent"]["weights_sha256"] == shipped["weights_sha256"]
    assert [site["seed"] for site in record["calibration"]["sites"]] == [181, 182, 183, 184]
    for name, label in columns.values():
        digest = results(name)["segmentation"]["checkpoint"]["digest"]
        expected = record["weights_sha256"] if label != "gpu-long2" else shipped["weights_sha256"]
        assert digest == expected[:16], name


def _check_speed_pairs(t: MarkdownTable, columns: dict[str, str], per_image: str, plain_row: str) -> None:
    """A table of `bench/segment_speed.py` runs before and after a change: each column its file's median
    seconds (plain, and mirror averaged) for the table's image size."""
    for column, name in columns.items():
        assert_names_source(t, name, "bench/segment_speed.py")
        figures = results(name)["checkpoints"]["gpu-long2"]
        index = t.header.index(column)
        assert_shows(row(t, plain_row)[index], [figures[per_image]], column)
        assert_shows(row(t, "mirror averaged")[index], [figures["flip_average_seconds"]], column)


def test_segmenting_faster_table() -> None:
    """The code before the inference copy and after it, two pairs of runs: each cell its file's median, the copy's
    ratio to the network as trained in the same rounds, and the mirror averaging under issue 23's 0.15 s now."""
    t = table("seconds per 512x288 image on one thread, median of 15 rounds", "Segmenting faster")
    columns = {
        "before, first pair": "segment_speed_before_inference.json",
        "now, first pair": "segment_speed_inference.json",
        "before, second pair": "segment_speed_before_inference_2.json",
        "now, second pair": "segment_speed_inference_2.json",
    }
    _check_speed_pairs(
        t, columns, "seconds_per_512x288_image", "plain: the network before, the stage's copy now"
    )
    for column, name in columns.items():
        figures = results(name)["checkpoints"]["gpu-long2"]
        as_trained = row(t, "plain: the network as trained")[t.header.index(column)]
        if column.startswith("now"):
            assert_shows(as_trained, [figures["as_trained_seconds"], figures["ratio_to_as_trained"]], column)
            assert figures["flip_average_target_met"] and figures["ratio_to_as_trained"] < 1
        else:
            assert "as_trained_seconds" not in figures and as_trained == "not timed"


def test_segmenting_1600_averaged_once_table() -> None:
    """Mirror averaging at 1600x900 before and after the probabilities are summed at the network's size, and the
    prose's ranges."""
    t = table("seconds per 1600x900 image on one thread, median of 5 rounds", "resizes the sum once")
    columns = {
        "before, first pair": "segment_speed_1600_before.json",
        "now, first pair": "segment_speed_1600.json",
        "before, second pair": "segment_speed_1600_before_2.json",
        "now, second pair": "segment_speed_1600_2.json",
    }
    _check_speed_pairs(t, columns, "seconds_per_1600x900_image", "plain: the stage's copy")
    for name in columns.values():
        assert results(name)["image_size"] == {"width": 1600, "height": 900}
    flip = {
        name: results(name)["checkpoints"]["gpu-long2"]["flip_average_seconds"] for name in columns.values()
    }
    assert max(flip["segment_speed_1600.json"], flip["segment_speed_1600_2.json"]) < 0.5 * min(
        flip["segment_speed_1600_before.json"], flip["segment_speed_1600_before_2.json"]
    )


MIRRORED_SITES = {
    "default twin": ("segment_default_twin.json", "default_twin"),
    "hilly twin": ("segment_hilly.json", "hilly"),
    **{seed: (f"segment_gpu_long2_{seed}.json", seed) for seed in ("9301", "9302", "9303", "9004", "9005")},
}


def test_segmenter_mirrored_by_default_table() -> None:
    """The plain network against its mirror-averaged masks, the stage's default, on the calibration table's seven
    sites; the prose's gains are the table's, and the mirrored runs are of the shipped checkpoint."""
    columns = {}
    for site, (plain, short) in MIRRORED_SITES.items():
        columns[f"{site} plain"] = (plain, "gpu-long2")
        columns[f"{site} mirrored"] = (f"segment_mirrored_{short}.json", "gpu-long2")
    _check_segmenter_columns("class, mirror averaging by default, seven unseen 512x288 sites", columns)
    shipped = json.loads((ROOT / "cama_pipeline/segment/shipped/checkpoint.json").read_text(encoding="utf-8"))
    gains: dict[str, list[float]] = {}
    for plain, short in MIRRORED_SITES.values():
        before = results(plain)["segmentation"]
        after = results(f"segment_mirrored_{short}.json")["segmentation"]
        assert after["flip_average"] is True
        assert before.get("flip_average") is not True
        assert after["checkpoint"]["digest"] == shipped["weights_sha256"][:16]
        for cls, value in after["per_class_iou"].items():
            gains.setdefault(cls, []).append(round(value, 3) - round(before["per_class_iou"][cls], 3))
    text = " ".join(readme_text().split())
    for cls in ("lane_marking", "crosswalk", "curb", "vehicle", "road"):
        low, high = min(gains[cls]), max(gains[cls])
        assert low > 0, cls
        assert f"{cls.replace('_', ' ')} +{low:.3f} to +{high:.3f}" in text, cls
    assert max(abs(g) for g in gains["ego"]) <= 0.001 + 1e-9


def test_whole_path_through_mirrored_masks_sentence() -> None:
    """The 9303 whole path through the mirror-averaged masks: its differences and tolerances as the prose gives
    them, and the run is of the new default."""
    recorded = results("segment_path_mirrored_9303.json")
    assert recorded["segmentation"]["flip_average"] is True
    d = recorded["differences"]
    m, e, r = (d[k]["predicted_minus_reference"] for k in ("proposal_map", "elevation_rmse_cm", "sre_ref_px"))
    assert d["proposal_map"]["met"] and d["elevation_rmse_cm"]["met"] and not d["sre_ref_px"]["met"]
    world, own = d["annotator_speed_up"], d["annotator_speed_up_in_reconstruction_frame"]
    text = " ".join(readme_text().split())
    assert "bench/results/segment_path_mirrored_9303.json" in text
    assert (
        f"proposal mAP {m:+.3f} (issue 23's tolerance 0.05), elevation RMSE {e:+.2f} cm (1 cm) and SRE "
        f"{r:+.2f} px at 960x540 (0.5 px, missed by {r - 0.5:.3f} px); the scripted annotator "
        f"{world['predicted']:.2f}x against {world['reference']:.2f}x, in the reconstruction's own frame "
        f"{own['predicted']:.2f}x against {own['reference']:.2f}x"
    ) in text


def test_photometric_split_table() -> None:
    t = table("site, poses, surface", "Where the photometric error lies")
    assert_names_source(t, "surface_photometric.json", "bench/surface_photometric.py")
    sites = results("surface_photometric.json")["sites"]
    names = {"default twin": "default-nomasks", "9301": "random512-9301-nomasks"}
    for label, cells in t.rows.items():
        site_name, poses, surface = label.split(", ")
        (runs,) = [runs for path, runs in sites.items() if path.endswith("/" + names[site_name])]
        source = {"true": "ground_truth", "SfM": "sfm"}[poses]
        run = runs[f"{source}, {surface}"]
        assert run["refine"] == (surface == "refined"), label
        scales = [run["by_scale"][f"sigma_{sigma}"] for sigma in ("1", "2", "4")]
        assert_shows(cells[1], [run["psnr_db"], run["psnr_affine_db"]], label)
        assert_shows(cells[2], [100 * scale["fine_share"] for scale in scales], label)
        assert_shows(cells[3], [scale["truth_blurred_psnr_db"] for scale in scales], label)
        for index, name in enumerate(("road", "lane_marking", "crosswalk", "curb"), start=4):
            figures = run["by_class"][name]
            assert_shows(cells[index], [figures["psnr_db"], figures["mean_over_truth"]], f"{label} {name}")
    assert len(t.rows) == 8


def test_sfm_point_error_table() -> None:
    t = table("SfM road points the surface may fit to: share: median height error, share beyond 10 cm")
    assert_names_source(t, "sfm_point_error.json", "bench/sfm_point_error.py")
    sites = results("sfm_point_error.json")["sites"]

    def shown(figures: dict[str, Any]) -> list[Expected]:
        return [100 * figures["share"], figures["median_cm"], 100 * figures["beyond_10cm"]]

    def kept_bin(site: dict[str, Any], name: str, lower: float) -> dict[str, Any]:
        (found,) = [b for b in site["kept_by"][name] if b["from"] == lower]
        return found

    bins = {
        f"kept, triangulated at {a}-{b} deg": ("triangulation_deg", a) for a, b in ((0, 2), (2, 3), (3, 5))
    }
    bins |= {
        f"kept, triangulated at {a}-{b} deg": ("triangulation_deg", a) for a, b in ((5, 8), (8, 12), (12, 20))
    }
    bins["kept, triangulated at 20 deg or more"] = ("triangulation_deg", 20)
    bins |= {
        f"kept, nearest camera {a}-{b} m": ("range_m", a) for a, b in ((5, 8), (8, 12), (12, 16), (16, 20))
    }
    bins |= {"kept, reprojection error 1-1.5 px": ("reprojection_px", 1.0)}
    bins |= {"kept, reprojection error 1.5-2 px": ("reprojection_px", 1.5)}
    for column, name in SURFACE_SITES.items():
        site, index = sites[name], t.header.index(column)
        where = f"SfM point error, {column}"
        cameras = [site["points"], site["camera_centres_after_similarity_cm"]]
        assert_shows(row(t, "points; camera centres after the similarity")[index], cameras, where)
        whole = [site["median_cm"], 100 * site["beyond_10cm"]]
        assert_shows(row(t, "all points: median, beyond 10 cm")[index], whole, where)
        assert_shows(row(t, "off the true road")[index], shown(site["off_true_road"]), where)
        assert_shows(row(t, "kept by the fit")[index], shown(site["kept_by_the_fit"]), where)
        for label, (name_of_property, lower) in bins.items():
            assert_shows(
                row(t, label)[index], shown(kept_bin(site, name_of_property, lower)), f"{where}, {label}"
            )
        for label in ("road", "crosswalk"):
            assert_shows(row(t, f"labelled {label}")[index], shown(site["by_label"][label]), where)
        # README's reading: the flattest-triangulated kept points are the worst of the angles up to 20 degrees
        angles = [b["median_cm"] for b in site["kept_by"]["triangulation_deg"] if b["to"] <= 20]
        assert angles[0] == max(angles), where


def test_sfm_reprojection_gate_table() -> None:
    t = table("SfM reprojection gate of the surface's points, SfM poses")
    assert_names_source(t, "surface_sfm_error_gate.json", "bench/surface_variants.py")
    sites = results("surface_sfm_error_gate.json")["sites"]
    _check_variant_columns(t, sites, "SfM reprojection gate table")
    for path, site in sites.items():  # README's reading: a tighter gate costs the twins' lane marking
        if path.endswith(("/hilly-nomasks", "/default-nomasks")):
            lane_marking = {
                name: run["iou_in_reconstruction_frame"]["lane_marking"] for name, run in site["runs"].items()
            }
            assert lane_marking["max error 1 px"] < lane_marking["shipped"], path


def test_extrapolated_heights_table() -> None:
    t = table("heights the report calls extrapolated, SfM poses")
    assert_names_source(t, "surface_extrapolated.json", "bench/surface_variants.py")
    sites = results("surface_extrapolated.json")["sites"]
    for column, name in SURFACE_SITES.items():
        (run,) = [site["runs"]["shipped"] for path, site in sites.items() if path.endswith("/" + name)]
        flagged, split = run["extrapolated_heights"], run["height_error_by_support"]
        index = t.header.index(column)
        expected = [100 * flagged["extrapolated_road_share"], flagged["farthest_m"]]
        assert_shows(
            row(t, "road cells with extrapolated heights (farthest fifth point)")[index], expected, column
        )
        assert_shows(row(t, "elevation RMSE on them")[index], [100 * split["extrapolated"]["rmse_m"]], column)
        other = row(t, "elevation RMSE on the other road cells")[index]
        assert_shows(other, [100 * split["supported"]["rmse_m"]], column)
        assert split["extrapolated"]["rmse_m"] > split["supported"]["rmse_m"], column  # README's reading
