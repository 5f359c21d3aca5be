"""The keyframes stage and `cama keyframes` on the tiny synthetic site."""

from pathlib import Path

from typer.testing import CliRunner

from cama_pipeline.data import load_dataset
from cama_pipeline.keyframes import KeyframeConfig
from cama_pipeline.keyframes import run as run_keyframes
from cama_pipeline.keyframes.io import read_keyframes
from cama_pipeline.wigo import WigoConfig
from cama_pipeline.wigo import run as run_wigo
from cama_studio.cli import app

runner = CliRunner()


def test_frames_within_40_ms_and_stationary_clip_kept_whole(site_root: Path, tmp_path: Path) -> None:
    root = site_root / "nuscenes"
    run_wigo(WigoConfig(), root, tmp_path, show_progress=False)
    result = run_keyframes(KeyframeConfig(), root, tmp_path)
    dataset = load_dataset(root, check_files=False)
    kinds = {s.name: s.description for s in dataset.scenes}
    for name, path in result.paths.items():
        kf = read_keyframes(path)
        assert result.item(name).report["keyframes"] == len(kf.keyframes)
        assert kf.max_time_diff_us <= 40_000
        assert all(f.time_diff_us <= 40_000 for f in kf.frames)
        assert len(kf.frames) == len(dataset.scene_by_name(name).images["CAM_FRONT"])
        if "stationary" in kinds[name]:
            assert kf.stationary and len(kf.keyframes) == len(kf.frames)
        else:
            assert not kf.stationary and 2 <= len(kf.keyframes) < len(kf.frames)
    again = run_keyframes(KeyframeConfig(), root, tmp_path)
    assert again.skipped == tuple(result.paths)
    assert [item.report for item in again.items] == [item.report for item in result.items]


def test_cli_keyframes_table_and_missing_wigo(site_root: Path, tmp_path: Path) -> None:
    root = str(site_root / "nuscenes")
    missing = runner.invoke(app, ["keyframes", root, "--workspace", str(tmp_path)])
    assert missing.exit_code == 2 and "cama wigo" in missing.output
    assert runner.invoke(app, ["wigo", root, "--workspace", str(tmp_path)]).exit_code == 0
    result = runner.invoke(app, ["keyframes", root, "--workspace", str(tmp_path), "--min-rotation-deg", "2"])
    assert result.exit_code == 0, result.output
    assert "scene-0001" in result.output
    bad = runner.invoke(app, ["keyframes", root, "--workspace", str(tmp_path), "--max-time-diff-ms", "0"])
    assert bad.exit_code == 2 and "max_time_diff_ms" in bad.output
