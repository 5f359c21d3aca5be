"""`cama export` over `cama_pipeline.export`: requests are checked before anything is written, a failing writer
leaves nothing, and the Lanelet2 format (no data set needed) goes through the whole path."""

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from annotations import AnnotationSet, Georeference, MapElement
from annotations.lanelet2_format import MapProjection
from cama_pipeline.bev import BevRasters, write_bev
from cama_pipeline.data.map_origins import NUSCENES_MAP_ORIGINS
from cama_pipeline.export import ExportFormat, ExportRequest, export
from cama_pipeline.export import run as export_run
from cama_pipeline.site.io import write_sites_index
from cama_pipeline.workspace import Workspace
from cama_studio.export_command import export_command
from tests.annotations.annotation_helpers import element_kwargs
from tests.annotations.kerb_helpers import KERB_GEOREF, kerb_raster, kerb_set

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


KERBS_LINE = "boundaries by kerb evidence {'observed': 1, 'none': 1, 'assumed': 2}"
LANELET2 = ["--format", "lanelet2", "--origin", "1.2990,103.7880"]


def _kerb_set_file(tmp_path: Path) -> Path:
    path = tmp_path / "kerbs.json"
    kerb_set().write_json(path)
    return path


@pytest.mark.parametrize("suffix", [".npy", ".png"])
def test_lanelet2_semantic_option_tells_kerbs_from_road_borders(tmp_path: Path, suffix: str) -> None:
    source, out, raster = _kerb_set_file(tmp_path), tmp_path / "map.osm", tmp_path / f"semantic{suffix}"
    if suffix == ".npy":
        np.save(raster, kerb_raster())
    else:
        cv2.imwrite(str(raster), kerb_raster())
    result = runner.invoke(app, ["export", str(source), str(out), *LANELET2, "--semantic", str(raster)])
    assert result.exit_code == 0, result.output
    assert KERBS_LINE in result.output and f"semantic raster: {raster}" in result.output
    osm = out.read_text(encoding="utf-8")
    assert osm.count('v="road_border"') == 1 and osm.count('v="curbstone"') == 3


def test_lanelet2_reads_the_surface_raster_of_the_export_site_by_default(tmp_path: Path) -> None:
    source, out = _kerb_set_file(tmp_path), tmp_path / "map.osm"
    workspace = Workspace(tmp_path / "ws")
    bev = workspace.surface_bev("site-002")
    write_bev(bev, BevRasters(KERB_GEOREF.as_raster(), semantic=kerb_raster()))
    sites = [{"site_id": "s"}, {"site_id": "site-002"}]  # "s": the annotation set's site
    write_sites_index(workspace.sites_index(), {"sites": sites, "dropped": []})
    args = ["export", str(source), str(out), *LANELET2, "--workspace", str(workspace.root)]
    # the annotation set's site (the poses' site) has no raster: no kerb evidence from another site's
    unrastered = runner.invoke(app, args)
    assert unrastered.exit_code == 0, unrastered.output
    assert "'assumed': 4} (semantic raster: none)" in unrastered.output
    result = runner.invoke(app, [*args, "--site-id", "site-002", "--overwrite"])
    assert result.exit_code == 0, result.output
    assert KERBS_LINE in result.output and str(bev) in result.output
    plain = runner.invoke(app, ["export", str(source), str(tmp_path / "plain.osm"), *LANELET2])
    assert plain.exit_code == 0, plain.output
    assert "{'observed': 0, 'none': 0, 'assumed': 4} (semantic raster: none)" in plain.output


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("small.npy", np.zeros((10, 10), dtype=np.uint8), r"shape \(10, 10\)"),
        ("float.npy", np.zeros((200, 200)), "integer class ids"),
        ("broken.png", b"not an image", "not a readable"),
        ("missing.npy", None, "No such file"),
    ],
)
def test_a_bad_semantic_raster_exits_2_naming_the_file(
    tmp_path: Path, name: str, content: np.ndarray | bytes | None, message: str
) -> None:
    source, raster = _kerb_set_file(tmp_path), tmp_path / name
    if isinstance(content, bytes):
        raster.write_bytes(content)
    elif content is not None:
        np.save(raster, content)
    result = runner.invoke(
        app, ["export", str(source), str(tmp_path / "map.osm"), *LANELET2, "--semantic", str(raster)]
    )
    assert result.exit_code == 2, result.output
    assert f"{raster}: cannot use as the semantic raster" in result.output
    assert re.search(message, result.output)
    assert not (tmp_path / "map.osm").exists()


def test_a_semantic_raster_is_only_for_lanelet2_and_of_the_set_shape(tmp_path: Path) -> None:
    annotations = kerb_set()
    with pytest.raises(ValueError, match="--semantic: only for --format lanelet2"):
        ExportRequest(annotations, tmp_path / "m.json", ExportFormat.maptr, tmp_path, semantic=kerb_raster())
    with pytest.raises(ValueError, match=r"semantic: semantic raster shape \(3, 3\)"):
        ExportRequest(
            annotations,
            tmp_path / "map.osm",
            format=ExportFormat.lanelet2,
            origin_lat_lon=(1.0, 2.0),
            semantic=np.zeros((3, 3), dtype=np.uint8),
        )


def _first_node_lat_lon(path: Path) -> tuple[float, float]:
    node = next(ET.parse(path).getroot().iter("node"))
    return float(node.get("lat", "nan")), float(node.get("lon", "nan"))


def _workspace_at(tmp_path: Path, location: str) -> Workspace:
    """A workspace whose only site, the annotation set's, lies at `location`."""
    workspace = Workspace(tmp_path / "ws")
    sites = [{"site_id": "site-a", "location": location, "scenes": ["scene-0001"]}]
    write_sites_index(workspace.sites_index(), {"sites": sites, "dropped": []})
    return workspace


def test_lanelet2_places_a_nuscenes_site_at_its_locations_origin(tmp_path: Path) -> None:
    source = _set_file(tmp_path)
    workspace = _workspace_at(tmp_path, "boston-seaport")
    out = tmp_path / "map.osm"
    base = ["export", str(source), str(out), "--format", "lanelet2", "--workspace", str(workspace.root)]
    result = runner.invoke(app, base)
    assert result.exit_code == 0, result.output
    boston = NUSCENES_MAP_ORIGINS["boston-seaport"]
    assert f"origin {list(boston)} (site site-a at boston-seaport), projection local" in result.output
    lat, lon = _first_node_lat_lon(out)  # global (101, 201): 101 m east, 201 m north of the origin
    assert abs(lat - boston[0]) < 0.01 and abs(lon - boston[1]) < 0.01
    named = runner.invoke(
        app, [*base, "--origin", "singapore-onenorth", "--projection", "utm", "--overwrite"]
    )
    assert named.exit_code == 0, named.output
    assert "(--origin singapore-onenorth), projection utm" in named.output
    assert abs(_first_node_lat_lon(out)[0] - NUSCENES_MAP_ORIGINS["singapore-onenorth"][0]) < 0.01


@pytest.mark.parametrize(
    ("location", "extra", "message"),
    [
        ("synthetic-default", [], "site 'site-a' lies at 'synthetic-default', whose map origin is not known"),
        ("boston-seaport", ["--site-id", "site-b"], "the site's location is unknown: --site-id 'site-b'"),
        ("boston-seaport", ["--origin", "boston"], "--origin 'boston': expected LAT,LON"),
        ("boston-seaport", ["--projection", "mercator"], "mercator"),
    ],
)
def test_lanelet2_without_a_known_origin_is_refused_naming_why(
    tmp_path: Path, location: str, extra: list[str], message: str
) -> None:
    source, workspace = _set_file(tmp_path), _workspace_at(tmp_path, location)
    args = ["export", str(source), str(tmp_path / "map.osm"), "--format", "lanelet2"]
    result = runner.invoke(app, [*args, "--workspace", str(workspace.root), *extra])
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.output.split())
    assert not (tmp_path / "map.osm").exists()


def test_origin_options_are_checked_by_the_request(tmp_path: Path) -> None:
    annotations = AnnotationSet.read_json(_set_file(tmp_path))
    lanelet2 = {"out": tmp_path / "map.osm", "format": ExportFormat.lanelet2}
    with pytest.raises(ValueError, match="either LAT,LON or a nuScenes location"):
        ExportRequest(annotations, **lanelet2, origin_lat_lon=(1.0, 2.0), origin_location="boston-seaport")
    with pytest.raises(ValueError, match="'mars': not LAT,LON nor a nuScenes location"):
        ExportRequest(annotations, **lanelet2, origin_location="mars")
    with pytest.raises(ValueError, match="only for --format lanelet2"):
        ExportRequest(
            annotations, tmp_path / "m.json", ExportFormat.maptr, tmp_path, projection=MapProjection.local
        )
