"""The sites stage and `cama sites` on the tiny synthetic site, after WIGO and keyframes."""

import json
from pathlib import Path

from typer.testing import CliRunner

from cama_pipeline.data import load_dataset
from cama_pipeline.keyframes import KeyframeConfig
from cama_pipeline.keyframes import run as run_keyframes
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.io import read_site_manifest, read_sites_index
from cama_pipeline.site.stage import run as run_sites
from cama_pipeline.wigo import WigoConfig
from cama_pipeline.wigo import run as run_wigo
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app

runner = CliRunner()


def test_overlapping_clips_one_site_night_dropped_stationary_merged(site_root: Path, tmp_path: Path) -> None:
    root = site_root / "nuscenes"
    dataset = load_dataset(root, check_files=False)
    kind = {
        s.name: s.description.split(",")[0 if "Night" in s.description else 1].strip() for s in dataset.scenes
    }
    moving = sorted(n for n, k in kind.items() if k == "moving")
    (stationary,) = [n for n, k in kind.items() if k == "stationary"]
    (night,) = [n for n, k in kind.items() if k == "Night"]
    run_wigo(WigoConfig(), root, tmp_path, show_progress=False)
    run_keyframes(KeyframeConfig(), root, tmp_path)
    result = run_sites(SiteConfig(), root, tmp_path, dataset=dataset)
    (site,) = result.items
    assert set(site.report["scenes"]) == {*moving, stationary}
    assert site.report["merged"][stationary] in moving
    ((dropped, reason),) = [(d["scene"], d["reason"]) for d in result.report["dropped"]]
    assert dropped == night and "night" in reason
    index = read_sites_index(result.workspace.sites_index())
    assert index == {"schema": "cama.sites/1", **result.report}
    manifest = read_site_manifest(site.path)
    scenes = {s["scene"]: s for s in manifest["scenes"]}
    assert scenes[stationary]["kind"] == "stationary" and scenes[stationary]["merged_into"] in moving
    assert all(f["keyframe"] for f in scenes[stationary]["frames"])
    images = {im.token for name in site.report["scenes"] for im in dataset.scene_by_name(name).all_images()}
    assert set(manifest["poses"]) == images
    for scene in manifest["scenes"]:
        for frame in scene["frames"]:
            assert all(token in manifest["poses"] for token in frame["images"].values())
    again = run_sites(SiteConfig(), root, tmp_path, dataset=dataset)
    assert again.skipped == (site.name,) and again.report == result.report


def test_cli_sites_needs_wigo_and_keyframes_first(site_root: Path, tmp_path: Path) -> None:
    root = str(site_root / "nuscenes")
    ws = ["--workspace", str(tmp_path)]
    missing = runner.invoke(app, ["sites", root, *ws])
    assert missing.exit_code == 2 and "cama wigo" in missing.output
    assert runner.invoke(app, ["wigo", root, *ws]).exit_code == 0
    no_keyframes = runner.invoke(app, ["sites", root, *ws])
    assert no_keyframes.exit_code == 2 and "cama keyframes" in no_keyframes.output
    assert runner.invoke(app, ["keyframes", root, *ws]).exit_code == 0
    result = runner.invoke(app, ["sites", root, *ws])
    assert result.exit_code == 0, result.output
    assert "site-001" in result.output and "dropped" in result.output
    assert json.loads(Workspace(tmp_path).sites_index().read_text())["schema"] == "cama.sites/1"
