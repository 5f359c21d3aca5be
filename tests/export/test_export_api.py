"""`cama export` over `cama_pipeline.export`: requests are checked before anything is written, a failing writer
leaves nothing, and the Lanelet2 format (no data set needed) goes through the whole path."""

from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from annotations import AnnotationSet, Georeference, MapElement
from cama_pipeline.export import ExportFormat, ExportRequest, export
from cama_pipeline.export import run as export_run
from cama_studio.export_command import export_command
from tests.annotations.annotation_helpers import element_kwargs

app = typer.Typer()
app.command("export")(export_command)
app.callback()(lambda: None)  # a group, so the command is called by its name as in `cama export`
runner = CliRunner()
GEOREF = Georeference(
    site_origin_xy=(100.0, 200.0), origin_xy=(100.0, 220.0), resolution=0.5, width=40, height=40
)


def _set_file(tmp_path: Path) -> Path:
    element = MapElement.model_validate(element_kwargs(points_2d=[[1.0, 1.0], [5.0, 2.0]]))
    path = tmp_path / "annotations.json"
    AnnotationSet(site_id="site-a", georeference=GEOREF, elements=[element]).write_json(path)
    return path


def test_lanelet2_through_the_command(tmp_path: Path) -> None:
    source, out = _set_file(tmp_path), tmp_path / "map.osm"
    args = ["export", str(source), str(out), "--format", "lanelet2", "--origin", "1.2990,103.7880"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "exported 1 elements (lanelet2" in result.output
    assert out.read_text(encoding="utf-8").startswith("<?xml")
    again = runner.invoke(app, args)
    assert again.exit_code == 2 and "--overwrite" in again.output
    assert runner.invoke(app, [*args, "--overwrite"]).exit_code == 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--format", "lanelet2"], "--origin"),
        (["--format", "lanelet2", "--origin", "north"], "LAT,LON"),
        (["--format", "maptr"], "--dataset"),
        (["--format", "nuscenes-cama"], "--dataset"),
        (["--format", "lanelet2", "--origin", "1,2", "--with-clip-data"], "--with-clip-data"),
        (["--format", "lanelet2", "--origin", "1,2", "--observed-radius-m", "0"], "--observed-radius-m"),
    ],
)
def test_bad_requests_exit_2_and_write_nothing(tmp_path: Path, extra: list[str], message: str) -> None:
    source = _set_file(tmp_path)
    result = runner.invoke(app, ["export", str(source), str(tmp_path / "out"), *extra])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["annotations.json"]


def test_failing_writer_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def half_then_fail(_inputs: object, staging: Path) -> dict[str, object]:
        staging.write_text("<osm>")
        raise ValueError("element e1: broken")

    monkeypatch.setitem(export_run.WRITERS, ExportFormat.lanelet2, half_then_fail)
    annotations = AnnotationSet.read_json(_set_file(tmp_path))
    request = ExportRequest(
        annotations, tmp_path / "map.osm", format=ExportFormat.lanelet2, origin_lat_lon=(1.0, 2.0)
    )
    with pytest.raises(ValueError, match="broken"):
        export(request)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["annotations.json"]
