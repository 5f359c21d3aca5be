"""The VMA commands of the `cama` CLI: propose, train, retrain, vma-eval, vma-split."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from annotations import AnnotationSet
from cama_studio.cli import app
from models.vma.propose import propose
from models.vma.rule_based import RuleConfig
from tests.vma.vma_test_sites import drawn_semantic, hand_drawn_site, write_raster_site

runner = CliRunner()


def test_propose_rule_based_writes_an_annotation_set_and_skips_when_up_to_date(
    drawn_site: Path, tmp_path: Path
) -> None:
    # a path over 200 characters and a narrow terminal: the message must still be one line (issue 20)
    out = tmp_path.joinpath(*(f"{'long-folder-name-' * 4}{i}" for i in range(4)), "proposals.json")
    assert len(str(out)) > 200
    result = runner.invoke(app, ["propose", str(drawn_site), "--proposer", "rule", "--out", str(out)])
    assert result.exit_code == 0, result.output
    proposals = AnnotationSet.read_json(out)
    assert {e.cls for e in proposals.elements} == {"divider", "boundary", "ped_crossing"}
    assert all(e.source == "proposal" and e.confidence is not None for e in proposals.elements)
    assert proposals.georeference.site_origin_xy == (500.0, 800.0)  # no manifest: the raster origin
    modified = out.stat().st_mtime_ns
    args = ["propose", str(drawn_site), "--proposer", "rule", "--out", str(out)]
    again = runner.invoke(app, args, env={"COLUMNS": "40"})
    assert again.exit_code == 0 and out.stat().st_mtime_ns == modified, again.output
    assert any(f"{out} (up to date, nothing done)" in line for line in again.output.splitlines())


def test_proposals_are_redone_when_settings_or_code_change(
    drawn_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "proposals.json"
    assert not propose(drawn_site, out, proposer="rule", show_progress=False).skipped
    assert propose(drawn_site, out, proposer="rule", show_progress=False).skipped
    kinked = RuleConfig(divider_min_radius_m=RuleConfig().divider_min_radius_m + 1.0)
    assert not propose(drawn_site, out, proposer="rule", rule=kinked, show_progress=False).skipped
    assert not propose(drawn_site, out, proposer="rule", min_confidence=0.2, show_progress=False).skipped
    monkeypatch.setattr("models.vma.propose.code_version", lambda package: f"{package} edited")
    assert not propose(drawn_site, out, proposer="rule", min_confidence=0.2, show_progress=False).skipped


def test_propose_reports_bad_input(tmp_path: Path) -> None:
    semantic, vectors = drawn_semantic()
    geo = {"origin_xy": [0.0, 0.0], "resolution": 0.1, "width": 10, "height": 10}
    site = write_raster_site(tmp_path / "site", semantic, vectors, geo)
    result = runner.invoke(
        app, ["propose", str(site), "--proposer", "rule", "--out", str(tmp_path / "p.json")]
    )
    assert result.exit_code == 2 and "wrong georeference" in result.output
    result = runner.invoke(app, ["propose", str(site), "--proposer", "magic"])
    assert result.exit_code == 2 and "--proposer" in result.output


def test_train_propose_eval_retrain(drawn_site: Path, tmp_path: Path) -> None:
    registry = tmp_path / "registry"
    result = runner.invoke(
        app,
        [
            "train",
            "--site",
            str(drawn_site),
            "--registry",
            str(registry),
            "--steps",
            "2",
            "--batch-size",
            "2",
        ],
    )
    assert result.exit_code == 0, result.output
    assert (registry / "v0001" / "model.pt").is_file() and (registry / "current.json").is_file()

    out = tmp_path / "learned.json"
    args = ["propose", str(drawn_site), "--checkpoint", str(registry), "--out", str(out)]
    # the default proposer is the element-mask network: a MapTR-style registry is named as such, not loaded
    wrong_kind = runner.invoke(app, args)
    assert wrong_kind.exit_code == 2 and "proposer 'learned'" in wrong_kind.output, wrong_kind.output
    assert not out.exists()
    result = runner.invoke(app, [*args, "--proposer", "learned", "--min-confidence", "0"])
    assert result.exit_code == 0, result.output
    assert AnnotationSet.read_json(out).site_id == "drawn"

    report = tmp_path / "eval.json"
    result = runner.invoke(app, ["vma-eval", str(drawn_site), "--proposer", "rule", "--out", str(report)])
    assert result.exit_code == 0 and report.is_file() and "mAP" in result.output

    rule = tmp_path / "rule.json"
    runner.invoke(app, ["propose", str(drawn_site), "--proposer", "rule", "--out", str(rule)])
    reviewed = AnnotationSet.read_json(rule)
    reviewed = reviewed.model_copy(
        update={"elements": [e.with_changes(review_state="accepted") for e in reviewed.elements]}
    )
    reviewed.write_json(rule)
    retrain = [
        "retrain",
        "--registry",
        str(registry),
        "--corrections",
        f"{drawn_site}={rule}",
        "--steps",
        "2",
    ]
    # the model trained on the drawn site: it may be neither scored nor gated on it
    seen = runner.invoke(
        app,
        [
            "vma-eval",
            str(drawn_site),
            "--proposer",
            "learned",
            "--checkpoint",
            str(registry),
            "--out",
            str(report),
        ],
    )
    assert seen.exit_code == 2 and "trained on this folder" in seen.output, seen.output
    refused = runner.invoke(app, [*retrain, "--val", str(drawn_site)])
    assert refused.exit_code == 2 and "trained on this folder" in refused.output, refused.output
    assert not (registry / "v0002").exists()
    validation = hand_drawn_site(tmp_path / "validation")
    result = runner.invoke(app, [*retrain, "--val", str(validation)])
    assert result.exit_code == 0, result.output
    assert (registry / "v0002" / "checkpoint.json").is_file()
    assert "candidate" in result.output


def test_retrain_rejects_malformed_corrections(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["retrain", "--registry", str(tmp_path), "--corrections", "nosign", "--val", str(tmp_path)]
    )
    assert result.exit_code == 2 and "SITE=ANNOTATIONS.json" in result.output


def test_split_of_a_one_location_data_set_is_refused(site_root: Path, tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["vma-split", str(site_root / "nuscenes"), "--out", str(tmp_path / "split.json")]
    )
    assert result.exit_code == 2 and "one location" in result.output


def test_propose_with_the_shipped_element_mask_network_from_any_directory(
    drawn_site: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "masks.json"
    result = runner.invoke(app, ["propose", str(drawn_site), "--proposer", "masks", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "shipped with the package" in result.output and "element_masks" in result.output
    proposals = AnnotationSet.read_json(out)
    assert {e.cls for e in proposals.elements} >= {"divider", "boundary"}
    assert {e.author for e in proposals.elements} == {f"vma-masks-{current_mask_version()}"}
    wrong_kind = Path(__file__).parents[2] / "models" / "vma" / "checkpoints"
    args = [
        "propose",
        str(drawn_site),
        "--proposer",
        "masks",
        "--checkpoint",
        str(wrong_kind),
        "--out",
        str(out),
    ]
    refused = runner.invoke(app, args)
    assert refused.exit_code == 2 and "not an 'element_masks' checkpoint" in refused.output
    unknown = runner.invoke(app, ["propose", str(drawn_site), "--proposer", "maptr", "--out", str(out)])
    assert unknown.exit_code == 2 and "learned, rule, masks" in unknown.output


def current_mask_version() -> str:
    """The promoted version of the shipped element-mask registry."""
    current = Path(__file__).parents[2] / "models" / "vma" / "element_masks" / "checkpoints" / "current.json"
    return str(json.loads(current.read_text())["version"])


def test_train_masks_names_a_site_without_vectors(tmp_path: Path) -> None:
    semantic, _ = drawn_semantic()
    site = write_raster_site(tmp_path / "novectors", semantic, [])
    (site / "ground_truth" / "vector_map.json").unlink()
    result = runner.invoke(
        app, ["train-masks", "--registry", str(tmp_path / "r"), "--site", str(site), "--steps", "1"]
    )
    assert result.exit_code == 2 and "vector_map.json" in result.output
    assert not (tmp_path / "r").exists()  # nothing half-written


def test_train_masks_refuses_a_reconstruction_share_without_reconstructions(tmp_path: Path) -> None:
    semantic, _ = drawn_semantic()
    site = write_raster_site(tmp_path / "bev", semantic, [])
    args = ["--site", str(site), "--steps", "1", "--reconstruction-share", "0.5"]
    result = runner.invoke(app, ["train-masks", "--registry", str(tmp_path / "r"), *args])
    assert result.exit_code == 2 and "reconstruction_share" in result.output
    assert "0 of 1 sites reconstructed" in " ".join(result.output.split())
    assert not (tmp_path / "r").exists()  # nothing half-written
