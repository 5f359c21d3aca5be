"""The pairs stage and `cama pairs` on the tiny synthetic site, after the upstream stages."""

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.io import read_pairs
from cama_pipeline.pairs.stage import run
from cama_studio.cli import app
from tests.pairs.site_workspace import build_site_workspace

runner = CliRunner()


@pytest.fixture(scope="module")
def workspace(tiny_site: object, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tiny_site.result.out_dir / "nuscenes"  # type: ignore[attr-defined]
    return build_site_workspace(root, tmp_path_factory.mktemp("pairs-ws"))


@pytest.fixture(scope="module")
def dataset_root(tiny_site: object) -> Path:
    return Path(tiny_site.result.out_dir) / "nuscenes"  # type: ignore[attr-defined]


def test_pairs_are_written_counted_and_skipped_when_up_to_date(dataset_root: Path, workspace: Path) -> None:
    first = run(PairsConfig(), dataset_root, workspace)
    (site,) = first.items
    assert not site.skipped and site.path == first.workspace.pairs_dir(site.name)
    stored = read_pairs(first.workspace.pairs_json(site.name))
    lines = first.workspace.pairs_txt(site.name).read_text().splitlines()
    counts = site.report["counts"]
    assert len(lines) == len(stored["pairs"]) == counts["total"] > 0
    assert counts["total"] == sum(counts[k] for k in ("temporal", "rig", "repeat", "hsp"))
    assert counts["total"] < 0.3 * counts["exhaustive"]
    assert all((dataset_root / name).is_file() for line in lines[:20] for name in line.split())
    assert all(name.split("/")[0] in ("samples", "sweeps") for line in lines for name in line.split())
    again = run(PairsConfig(), dataset_root, workspace)
    assert again.skipped == (site.name,) and again.items[0].report == site.report
    assert not run(PairsConfig(min_footprint_overlap=0.5), dataset_root, workspace).skipped


def test_cross_clip_pairs_exist_on_the_tiny_site(dataset_root: Path, workspace: Path) -> None:
    result = run(PairsConfig(), dataset_root, workspace)
    stored = read_pairs(result.workspace.pairs_json(result.items[0].name))
    hsp = [p for p in stored["pairs"] if p[2] == "hsp"]
    assert hsp and stored["hsp_funnel"]["kept"] == len(hsp)


def test_cli_and_missing_upstream_stage(dataset_root: Path, workspace: Path, tmp_path: Path) -> None:
    done = runner.invoke(app, ["pairs", str(dataset_root), "--workspace", str(workspace)])
    assert done.exit_code == 0, done.output
    assert "site-001" in done.output
    missing = runner.invoke(app, ["pairs", str(dataset_root), "--workspace", str(tmp_path)])
    assert missing.exit_code == 2 and "cama sites" in missing.output
    bad = runner.invoke(app, ["pairs", str(dataset_root), "--workspace", str(workspace), "--max-dz-m", "0"])
    assert bad.exit_code == 2 and "max_dz_m" in bad.output
