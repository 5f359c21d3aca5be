"""`cama export` / `cama import` through a small Typer app: CAMA and MapTR round trips, errors exit 2."""

from pathlib import Path

import numpy as np
import typer
from typer.testing import CliRunner

from annotations import AnnotationSet, Georeference, MapElement
from cama_studio.export_command import export_command, import_command
from tests.annotations.annotation_helpers import element_kwargs
from tests.data.nuscenes_fixture import write_nuscenes_fixture

app = typer.Typer()
app.command("export")(export_command)
app.command("import")(import_command)
runner = CliRunner()


def _write_set(tmp_path: Path, georef: Georeference) -> Path:
    """An annotation set JSON with one divider."""
    element = MapElement.model_validate(element_kwargs(points_2d=[[1.0, 1.0], [5.0, 2.0]]))
    path = tmp_path / "annotations.json"
    AnnotationSet(site_id="site-a", georeference=georef, elements=[element]).write_json(path)
    return path


def test_cama_export_import(tmp_path: Path, georef: Georeference, plane_elevation: np.ndarray) -> None:
    """Export to the CAMA release layout with a raster (logged poses: the fixture has no reconstruction),
    import the scene folder back: same ids, 3D points lifted."""
    source = _write_set(tmp_path, georef)
    dataset = write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=3, with_can=False, with_lidar=False)
    np.save(tmp_path / "elevation.npy", plane_elevation)
    args = ["export", str(source), str(tmp_path / "out"), "--elevation", str(tmp_path / "elevation.npy")]
    result = runner.invoke(app, [*args, "--dataset", str(dataset.root), "--poses", "coarse"])
    assert result.exit_code == 0, result.output
    scenes = sorted(p.name for p in (tmp_path / "out/all_clips").iterdir())
    assert scenes == ["scene-0001"]
    result = runner.invoke(
        app, ["import", str(tmp_path / "out/all_clips/scene-0001"), "--out", str(tmp_path / "back.json")]
    )
    assert result.exit_code == 0, result.output
    back = AnnotationSet.read_json(tmp_path / "back.json")
    assert [e.id for e in back.elements] == ["el-1"] and back.elements[0].points_3d is not None


def test_maptr_export_import(tmp_path: Path, georef: Georeference) -> None:
    """MapTR export needs a data set; import writes one element per exported vector."""
    source = _write_set(tmp_path, georef)
    fixture = write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=2, with_can=False, with_lidar=False)
    out = tmp_path / "maptr.json"
    result = runner.invoke(
        app,
        [
            "export",
            str(source),
            str(out),
            "--format",
            "maptr",
            "--dataset",
            str(fixture.root),
            "--poses",
            "coarse",
        ],
    )
    assert result.exit_code == 0, result.output
    result = runner.invoke(
        app, ["import", str(out), "--format", "maptr", "--out", str(tmp_path / "back.json")]
    )
    assert result.exit_code == 0, result.output
    assert len(AnnotationSet.read_json(tmp_path / "back.json").elements) == 2


def test_errors_exit_2(tmp_path: Path, georef: Georeference) -> None:
    """maptr without a data set, a missing folder and a bad file: `error: ...` naming it, exit code 2."""
    source = _write_set(tmp_path, georef)
    result = runner.invoke(app, ["export", str(source), str(tmp_path / "m.json"), "--format", "maptr"])
    assert result.exit_code == 2 and "error: --format maptr needs --dataset" in result.output
    result = runner.invoke(app, ["import", str(tmp_path / "nowhere"), "--out", str(tmp_path / "b.json")])
    assert result.exit_code == 2 and "georeference.json" in result.output
    (tmp_path / "bad.json").write_text("{}")
    result = runner.invoke(app, ["export", str(tmp_path / "bad.json"), str(tmp_path / "o")])
    assert result.exit_code == 2 and "error:" in result.output and "bad.json" in result.output
