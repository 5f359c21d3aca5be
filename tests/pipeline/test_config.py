"""The whole run's configuration: TOML/YAML files checked key by key, `--print-config` round-trips, every stage
gets its table, and a changed parameter reruns its stage and the ones after it only."""

import dataclasses
import json
import tomllib
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.keyframes.config import KeyframeConfig
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.segment.config import SegmentConfig
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from cama_studio.config import (
    ConfigError,
    PipelineConfig,
    ProposeConfig,
    dump_toml,
    load_config,
    to_table,
)
from cama_studio.pipeline import run
from models.vma.propose import ProposeResult
from models.vma.rule_based import RuleConfig


def _write(tmp_path: Path, text: str, name: str = "run.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _changed() -> PipelineConfig:
    """A configuration away from the defaults in every kind of field."""
    return PipelineConfig(
        executor="ray",
        workers=3,
        proposer="rule",
        checkpoint=Path("/models/vma/v7"),
        surface_poses="wigo",
        masks="masks/from-oneformer",
        scenes=("scene-0061", "scene-0103"),
        segment=SegmentConfig(batch_size=2, device="cpu"),
        features=FeaturesConfig(max_num_features=1024, masked_classes=(5,), matcher="colmap"),
        sfm=SfmConfig(first_ba_max_iterations=None, loss="huber"),
        propose=ProposeConfig(boundary_source="curb", rule=RuleConfig(join_gap_m=5.5)),
    )


@pytest.mark.parametrize("config", [PipelineConfig(), _changed()], ids=["defaults", "changed"])
def test_the_printed_configuration_reads_back_equal(config: PipelineConfig, tmp_path: Path) -> None:
    text = dump_toml(config)
    assert load_config(_write(tmp_path, text)) == config
    yaml_file = _write(tmp_path, yaml.safe_dump(tomllib.loads(text)), "run.yaml")
    assert load_config(yaml_file) == config


def test_a_file_sets_only_what_it_names_and_numbers_keep_their_fingerprint(tmp_path: Path) -> None:
    path = _write(
        tmp_path, "workers = 4\n[wigo]\nnode_rate_hz = 10\n[propose.inference.merge]\njoin_gap_m = 2\n"
    )
    config = load_config(path)
    assert config.workers == 4 and config.propose.inference.merge.join_gap_m == 2.0
    joint = load_config(
        _write(tmp_path, "[surface.joint]\nepochs = 2\nsearch_m = [0.1, 0.2]\n", "joint.toml")
    )
    assert joint.surface.joint.epochs == 2 and joint.surface.joint.search_m == (0.1, 0.2)
    assert config.wigo == PipelineConfig().wigo and isinstance(config.wigo.node_rate_hz, float)
    assert dataclasses.replace(config, workers=2, propose=ProposeConfig()) == PipelineConfig()


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("[sfm]\nmax_iteration = 3\n", ["sfm.max_iteration", "did you mean 'max_iterations'"]),
        ("[sfmm]\nrigid = false\n", ["'sfmm'", "'sfm'"]),
        ("[features]\nmax_num_features = 'many'\n", ["features.max_num_features", "an integer"]),
        ("[sfm]\nrigid = 1\n", ["sfm.rigid", "true or false"]),
        ("[wigo]\nlogged_pose_sigmas = [0.3, 0.1]\n", ["wigo.logged_pose_sigmas", "4 values"]),
        ("[surface]\ndevice = 'tpu'\n", ["surface.device", "'cuda'"]),
        ("[surface.refine]\nsweeps = [[0.02, 0.05]]\n", ["[surface.refine]", "RefineConfig.sweeps"]),
        ("[surface.refine]\nsweeps = [[0.02]]\n", ["surface.refine.sweeps"]),
        ("[surface.joint]\nepochs = -1\n", ["[surface.joint]", "JointConfig.epochs must be >= 0"]),
        ("[sfm]\nmax_iterations = 0\n", ["[sfm]", "SfmConfig.max_iterations must be >= 1"]),
        ("executor = 'cloud'\n", ["executor", "'ray'"]),
        ("masks = ''\n", ["masks must be auto, dataset, predicted, imported or a folder"]),
        ("masks = 3\n", ["masks must be a string"]),
        ("wigo = 3\n", ["wigo must be a table"]),
        ("[propose.rule]\nboundary_source = 'curb'\n", ["propose.rule.boundary_source"]),
        ("[sfm\n", ["not valid TOML"]),
        ("scenes = ['scene-1', 'scene-1']\n", ["scenes names a scene twice"]),
        ("scenes = 'scene-1'\n", ["scenes must be a list"]),
    ],
)
def test_a_bad_key_or_value_is_refused_naming_file_and_key(
    tmp_path: Path, text: str, named: list[str]
) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as refused:
        load_config(path)
    assert str(refused.value).startswith(f"{path}: ")
    for part in named:
        assert part in str(refused.value)


def test_a_yaml_number_without_a_dot_is_refused_not_misread(tmp_path: Path) -> None:
    """PyYAML reads 1e-6 as a string: refused with the key, never passed on as text."""
    path = _write(tmp_path, "sfm:\n  ba_function_tolerance: 1e-6\n", "run.yml")
    with pytest.raises(ConfigError, match="sfm.ba_function_tolerance must be a number"):
        load_config(path)


def test_print_config_shows_the_effective_configuration_and_exits_0(tmp_path: Path) -> None:
    runner = CliRunner()
    plain = runner.invoke(app, ["run", "--print-config"])
    assert plain.exit_code == 0, plain.output
    assert plain.output == dump_toml(PipelineConfig())
    path = _write(tmp_path, "[sfm]\nrigid = false\n[features]\nmax_num_features = 2048\n")
    argv = ["run", "--config", str(path), "--max-features", "512", "--proposer", "rule", "--print-config"]
    effective = runner.invoke(app, [*argv, "--masks", "imported"])
    assert effective.exit_code == 0, effective.output
    assert 'masks = "imported"' in effective.output.splitlines()
    printed = load_config(_write(tmp_path, effective.output, "printed.toml"))
    assert printed == PipelineConfig(
        proposer="rule",
        masks="imported",
        sfm=SfmConfig(rigid=False),
        features=FeaturesConfig(max_num_features=512),
    )
    empty = runner.invoke(app, ["run", "--masks", "", "--print-config"])
    assert empty.exit_code == 2 and "--masks" in empty.output
    chosen = runner.invoke(app, ["run", "--scene", "scene-0061", "--scene", "scene-0103", "--print-config"])
    assert chosen.exit_code == 0, chosen.output
    assert 'scenes = ["scene-0061", "scene-0103"]' in chosen.output.splitlines()
    twice = runner.invoke(app, ["run", "--scene", "scene-0061", "--scene", "scene-0061", "--print-config"])
    assert twice.exit_code == 2 and "--scene" in twice.output


def test_cama_run_refuses_a_bad_config_file_with_exit_2(tmp_path: Path) -> None:
    runner = CliRunner()
    path = _write(tmp_path, "[pairs]\nknn_radius = 30.0\n")
    bad = runner.invoke(app, ["run", str(tmp_path), "--config", str(path)])
    assert bad.exit_code == 2
    assert "pairs.knn_radius" in bad.output and str(path) in bad.output
    missing = runner.invoke(app, ["run", str(tmp_path), "--config", str(tmp_path / "none.toml")])
    assert missing.exit_code == 2 and "none.toml" in missing.output
    no_dataset = runner.invoke(app, ["run"])
    assert no_dataset.exit_code == 2 and "DATASET" in no_dataset.output


def test_to_table_hides_what_another_field_decides() -> None:
    table = to_table(PipelineConfig())
    assert "boundary_source" not in table["propose"]["rule"] and "rule" not in table["propose"]["inference"]
    assert table["checkpoint"] == "" and table["sites"]["night_keywords"] == ["night"]


STAGE_RUNS = {
    "wigo": "cama_pipeline.wigo.run",
    "keyframes": "cama_pipeline.keyframes.run",
    "sites": "cama_pipeline.site.stage.run",
    "pairs": "cama_pipeline.pairs.stage.run",
    "features": "cama_pipeline.features.stage.run",
    "sfm": "cama_pipeline.sfm.stage.run",
    "surface": "cama_pipeline.surface.run",
}
"""What `cama run` calls for each stage (the names it imports them by)."""


def test_each_stage_runs_with_its_table_of_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    config = load_config(
        _write(
            tmp_path,
            """
            workers = 3
            surface_poses = "wigo"
            masks = "dataset"
            scenes = ["scene-0061"]
            [wigo]
            node_rate_hz = 5.0
            [keyframes]
            min_translation_m = 1.0
            [sites]
            overlap_radius_m = 20.0
            [pairs]
            knn_radius_m = 30.0
            [features]
            max_num_features = 512
            [sfm]
            loss_scale_px = 2.0
            [sfm_merge]
            max_error_m = 0.5
            [surface]
            refit_iterations = 100
            [propose]
            min_confidence = 0.2
            boundary_source = "curb"
            [propose.rule]
            join_gap_m = 5.0
            """.replace("\n            ", "\n"),
        )
    )
    calls: dict[str, tuple[tuple[Any, ...], dict[str, Any]]] = {}
    for stage, target in STAGE_RUNS.items():
        monkeypatch.setattr(target, lambda *a, _stage=stage, **k: calls.setdefault(_stage, (a, k)))

    def propose(*args: Any, **kwargs: Any) -> ProposeResult:
        calls["propose"] = (args, kwargs)
        return ProposeResult(Path(args[1]), 0, 0.0, skipped=True, checkpoint=None)

    monkeypatch.setattr("models.vma.propose.propose", propose)
    workspace = Workspace(tmp_path / "workspace")
    workspace.sites_index().parent.mkdir(parents=True)
    index = {"schema": "cama.sites/1", "sites": [{"site_id": "site-001"}], "dropped": []}
    workspace.sites_index().write_text(json.dumps(index))
    (tmp_path / "nuscenes" / "semantic").mkdir(parents=True)  # the data set's masks: no segment stage
    result = run(tmp_path / "nuscenes", workspace.root, config)

    for stage in ("wigo", "keyframes", "sites", "pairs", "features", "sfm", "surface"):
        assert calls[stage][0][0] == getattr(config, stage), stage
    assert result.skipped == {"segment": "--masks dataset"} and "segment" in result.seconds
    assert all(calls[stage][1]["masks"] == "dataset" for stage in ("features", "sfm", "surface"))
    assert calls["sfm"][1]["merge_config"] == config.sfm_merge and calls["sfm"][1]["workers"] == 3
    assert calls["surface"][1]["poses"] == "wigo"
    assert all(calls[stage][1]["scenes"] == ("scene-0061",) for stage in ("wigo", "keyframes", "sites"))
    proposed = calls["propose"][1]
    assert proposed["min_confidence"] == 0.2 and proposed["inference"] == config.propose.inference
    assert proposed["rule"] == RuleConfig(join_gap_m=5.0, boundary_source="curb")


def test_the_segment_stage_runs_with_its_table_when_the_masks_need_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = load_config(_write(tmp_path, 'masks = "predicted"\nworkers = 3\n[segment]\nbatch_size = 4\n'))
    assert config.segment == SegmentConfig(batch_size=4)
    for stage in ("wigo", "keyframes", "sites", "pairs"):
        monkeypatch.setattr(STAGE_RUNS[stage], lambda *a, **k: None)
    calls: list[tuple[tuple[Any, ...], dict[str, Any]]] = []
    monkeypatch.setattr("cama_pipeline.segment.stage.run", lambda *a, **k: calls.append((a, k)))
    result = run(tmp_path / "nuscenes", tmp_path / "workspace", config, stop_after="segment")
    ((args, kwargs),) = calls
    assert args[0] == config.segment and kwargs["workers"] == 3 and kwargs["executor"] == "local"
    assert kwargs["scenes"] is None  # every scene: the file names none
    assert list(result.seconds)[-1] == "segment" and result.skipped == {}


def _outputs_by_folder(workspace: Path) -> dict[str, dict[str, int]]:
    """mtime_ns of every file of the workspace, by its top-level folder (a stage's outputs)."""
    folders: dict[str, dict[str, int]] = {}
    for path in sorted(workspace.rglob("*")):
        if path.is_file():
            relative = path.relative_to(workspace)
            folders.setdefault(relative.parts[0], {})[str(relative)] = path.stat().st_mtime_ns
    return folders


def test_a_changed_stage_parameter_reruns_that_stage_and_those_after_not_before(
    site_root: Path, tmp_path: Path
) -> None:
    """Real stages on the tiny site, up to the pairs: [keyframes] changed reruns keyframes, sites and pairs,
    and leaves WIGO's poses alone; [pairs] changed then reruns the pairs only."""
    dataset, workspace = site_root / "nuscenes", tmp_path / "workspace"
    run(dataset, workspace, PipelineConfig(), stop_after="pairs")
    first = _outputs_by_folder(workspace)
    assert {"wigo", "keyframes", "sites", "pairs"} <= set(first)

    keyframes = PipelineConfig(keyframes=KeyframeConfig(min_translation_m=1.5))
    run(dataset, workspace, keyframes, stop_after="pairs")
    second = _outputs_by_folder(workspace)
    assert second["wigo"] == first["wigo"]
    for folder in ("keyframes", "sites", "pairs"):
        assert second[folder] != first[folder], f"{folder} was not rerun"

    pairs = dataclasses.replace(keyframes, pairs=PairsConfig(knn_radius_m=35.0))
    run(dataset, workspace, pairs, stop_after="pairs")
    third = _outputs_by_folder(workspace)
    assert {f: third[f] for f in ("wigo", "keyframes", "sites")} == {
        f: second[f] for f in ("wigo", "keyframes", "sites")
    }
    assert third["pairs"] != second["pairs"]
