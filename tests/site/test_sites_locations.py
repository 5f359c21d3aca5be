"""The sites stage on the tiny site whose log table puts one of two overlapping scenes in another city: two
sites, each recording its location, as nuScenes' cities each have their own map frame."""

import json
import shutil
from pathlib import Path

from cama_pipeline.data import load_dataset
from cama_pipeline.keyframes import KeyframeConfig
from cama_pipeline.keyframes import run as run_keyframes
from cama_pipeline.site.aggregate import track_distance_m
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.io import read_site_manifest, read_sites_index
from cama_pipeline.site.stage import run as run_sites
from cama_pipeline.wigo import WigoConfig
from cama_pipeline.wigo import run as run_wigo
from cama_pipeline.wigo.inputs import clip_inputs

OTHER_CITY = "singapore-onenorth"


def _with_other_city(site_root: Path, out: Path, scene_name: str) -> Path:
    """A copy of the tiny data set's tables and CAN files (images linked) whose `scene_name` is logged in
    OTHER_CITY; returns the copy's root."""
    source = site_root / "nuscenes"
    root = out / "nuscenes"
    shutil.copytree(source / "v1.0-synth", root / "v1.0-synth")
    shutil.copytree(source / "can_bus", root / "can_bus")
    for folder in ("samples", "sweeps"):
        (root / folder).symlink_to(source / folder, target_is_directory=True)
    scenes = json.loads((root / "v1.0-synth" / "scene.json").read_text())
    log_token = next(s["log_token"] for s in scenes if s["name"] == scene_name)
    logs_path = root / "v1.0-synth" / "log.json"
    logs = json.loads(logs_path.read_text())
    for log in logs:
        if log["token"] == log_token:
            log["location"] = OTHER_CITY
    logs_path.write_text(json.dumps(logs))
    return root


def test_overlapping_scenes_of_two_cities_make_two_sites(site_root: Path, tmp_path: Path) -> None:
    original = load_dataset(site_root / "nuscenes", check_files=False)
    moving = [s.name for s in original.scenes if ", moving" in s.description and "Night" not in s.description]
    first, second = moving[:2]
    root = _with_other_city(site_root, tmp_path / "data", second)
    dataset = load_dataset(root, check_files=False)
    home = dataset.scene_by_name(first).location
    assert dataset.scene_by_name(second).location == OTHER_CITY != home
    # the two scenes' logged tracks overlap: one site if their locations were the same
    a, b = (clip_inputs(dataset.scene_by_name(n)).cameras.translation for n in (first, second))
    assert track_distance_m(a, b) < 15.0
    workspace = tmp_path / "ws"
    run_wigo(WigoConfig(), root, workspace, show_progress=False)
    run_keyframes(KeyframeConfig(), root, workspace)
    result = run_sites(SiteConfig(), root, workspace, dataset=dataset)
    by_location = {site.report["location"]: site.report for site in result.items}
    assert set(by_location) == {home, OTHER_CITY}
    assert second not in by_location[home]["scenes"] and first in by_location[home]["scenes"]
    assert by_location[OTHER_CITY]["scenes"] == [second]
    index = read_sites_index(result.workspace.sites_index())
    assert {entry["site_id"]: entry["location"] for entry in index["sites"]} == {
        site.name: site.report["location"] for site in result.items
    }
    for site in result.items:
        assert read_site_manifest(site.path)["location"] == site.report["location"]
