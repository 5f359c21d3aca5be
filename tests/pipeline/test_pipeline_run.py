"""`cama run`: stages in order with their times; a failure names its stage; the full path on the tiny site."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.code_version import CodeChangedError
from cama_pipeline.data import load_dataset
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from cama_studio.config import PipelineConfig
from cama_studio.pipeline import STAGES, PipelineError, PipelineResult, run


def test_the_path_runs_in_order_up_to_the_asked_stage_and_reruns_skip(
    site_root: Path, tmp_path: Path
) -> None:
    seen: list[str] = []
    result = run(site_root / "nuscenes", tmp_path / "ws", stop_after="sites", on_stage=seen.append)
    assert seen == ["wigo", "keyframes", "sites"] == list(result.seconds)
    index = json.loads(Workspace(tmp_path / "ws").sites_index().read_text())
    assert index["sites"]
    again = run(site_root / "nuscenes", tmp_path / "ws", stop_after="sites")
    assert again.seconds["wigo"] < result.seconds["wigo"] + 5.0


def test_a_run_on_named_scenes_works_on_those_only(
    site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`scenes` (`cama run --scene`): WIGO, keyframes and sites see the named scene alone, and the stages after
    the sites load only the sites' scenes of the data set."""
    import cama_pipeline.pairs.stage as pairs_stage

    chosen = load_dataset(site_root / "nuscenes", check_files=False).scenes[0].name
    loaded: list[object] = []
    load = pairs_stage.load_dataset
    monkeypatch.setattr(
        pairs_stage, "load_dataset", lambda *a, **k: loaded.append(k["scenes"]) or load(*a, **k)
    )
    ws = Workspace(tmp_path / "ws")
    run(site_root / "nuscenes", ws.root, PipelineConfig(scenes=(chosen,)), stop_after="pairs")
    assert ws.wigo_scenes() == [chosen]
    index = json.loads(ws.sites_index().read_text())
    assert [scene for site in index["sites"] for scene in site["scenes"]] == [chosen]
    assert loaded == [[chosen]]
    with pytest.raises(PipelineError, match="scene-no-such") as unknown:
        run(site_root / "nuscenes", ws.root, PipelineConfig(scenes=("scene-no-such",)), stop_after="wigo")
    assert unknown.value.bad_input and unknown.value.stage == "wigo"


def test_a_failing_stage_is_named(tmp_path: Path) -> None:
    with pytest.raises(PipelineError, match="stage wigo stopped on bad input") as missing:
        run(tmp_path / "no-such-dataset", tmp_path / "ws", stop_after="wigo")
    assert missing.value.bad_input and missing.value.stage == "wigo"
    with pytest.raises(ValueError, match="stop_after"):
        run(tmp_path, stop_after="everything")


def test_cama_run_reports_a_bad_option_and_a_missing_dataset(tmp_path: Path) -> None:
    runner = CliRunner()
    bad = runner.invoke(app, ["run", str(tmp_path), "--executor", "cloud"])
    assert bad.exit_code == 2 and "--executor" in bad.output
    missing = runner.invoke(app, ["run", str(tmp_path / "none"), "--stop-after", "wigo"])
    assert missing.exit_code == 2 and "stage wigo stopped on bad input" in missing.output


@pytest.mark.slow
def test_the_whole_path_on_the_tiny_site_ends_with_proposals(whole_path: PipelineResult) -> None:
    workspace, proposals = Workspace(whole_path.workspace), whole_path.proposals
    assert list(whole_path.seconds) == list(STAGES) and proposals
    for site_id, path in proposals.items():
        assert path == workspace.proposals(site_id) and path.is_file()
        assert (workspace.surface_bev(site_id) / "semantic.png").is_file()
        assert workspace.sfm_points(site_id).is_file()


def test_code_changed_under_the_run_stops_it_as_bad_input(
    site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stage whose code digest is refused (a file changed on disk after the process imported it) stops the run
    with exit 2 naming the file: the fix is the caller's (restart), not the stage's work."""
    import cama_pipeline.wigo.stage as wigo_stage

    def changed(package: str) -> str:
        raise CodeChangedError(f"{package}/fusion.py: changed on disk after this process imported it")

    monkeypatch.setattr(wigo_stage, "code_version", changed)
    result = CliRunner().invoke(
        app, ["run", str(site_root / "nuscenes"), "--workspace", str(tmp_path / "ws")]
    )
    assert result.exit_code == 2, result.output
    assert "fusion.py: changed on disk after this process imported it" in " ".join(result.output.split())
