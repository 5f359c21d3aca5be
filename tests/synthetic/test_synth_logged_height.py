"""`logged_height=False` (`cama synth --no-logged-height`): every logged ego pose has z = 0, as nuScenes' 2D
localization logs it; nothing else changes (the horizontal poses, the CAN files, the truth); recorded in the
manifest and the fingerprint; and WIGO on it leaves the height to the odometry."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.data.loader import load_dataset
from cama_pipeline.synthetic.generate import MANIFEST, SynthResult, fingerprint, run
from cama_pipeline.wigo import WigoConfig
from cama_pipeline.wigo import run as wigo
from cama_pipeline.wigo.io import read_wigo
from cama_studio.cli import app
from tests.synthetic.synth_helpers import file_digests, micro_config

EGO_POSE_TABLE = "ego_pose.json"


@pytest.fixture(scope="module")
def sites(tmp_path_factory: pytest.TempPathFactory) -> tuple[SynthResult, SynthResult]:
    """The micro config's tables with logged heights and without (no images: the tables are what differ)."""
    root = tmp_path_factory.mktemp("logged-height")
    logged = run(micro_config(), root / "logged", images=False, workers=1, show_progress=False)
    planar = run(micro_config(), root / "planar", images=False, logged_height=False, show_progress=False)
    return logged, planar


def _ego_poses(site: SynthResult) -> dict[str, dict]:
    path = next(site.dataset_root.rglob(EGO_POSE_TABLE))
    return {record["token"]: record for record in json.loads(path.read_text())}


def test_only_the_logged_heights_change(sites):
    logged, planar = sites
    differ = {
        path
        for path, digest in file_digests(planar.out_dir).items()
        if file_digests(logged.out_dir).get(path) != digest
    }
    assert {path.rsplit("/", 1)[-1] for path in differ} == {EGO_POSE_TABLE}
    with_height, without = _ego_poses(logged), _ego_poses(planar)
    assert with_height.keys() == without.keys()
    heights = np.array([record["translation"][2] for record in with_height.values()])
    assert np.abs(heights).max() > 0.01  # the site's logged poses do climb
    for token, record in without.items():
        assert record["translation"][2] == 0.0
        assert record["translation"][:2] == with_height[token]["translation"][:2]
        assert record["rotation"] == with_height[token]["rotation"]


def test_manifest_fingerprint_and_result_record_it(sites):
    logged, planar = sites
    assert json.loads((planar.out_dir / MANIFEST).read_text())["logged_height"] is False
    assert json.loads((logged.out_dir / MANIFEST).read_text())["logged_height"] is True
    assert not planar.logged_height and logged.logged_height
    assert fingerprint(micro_config(), logged_height=False) != fingerprint(micro_config())
    again = run(micro_config(), planar.out_dir, images=False, logged_height=False, show_progress=False)
    assert again.skipped and not again.logged_height


def test_wigo_leaves_the_height_free_on_it(sites, tmp_path):
    logged, planar = sites
    for site, expected in ((planar, "free"), (logged, "fused")):
        result = wigo(WigoConfig(), site.dataset_root, tmp_path / site.out_dir.name, show_progress=False)
        for scene in load_dataset(site.dataset_root, check_files=False).scenes:
            report = read_wigo(result.paths[scene.name]).report
            assert report["logged_pose_height"].startswith(expected), scene.name


@pytest.mark.slow
def test_cli_says_the_logged_poses_have_no_heights(tmp_path):
    out = tmp_path / "planar"
    args = ["synth", "--preset", "tiny", "--no-masks", "--no-logged-height", "--no-images", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "without heights: z = 0" in result.output
    assert json.loads((out / MANIFEST).read_text())["logged_height"] is False
