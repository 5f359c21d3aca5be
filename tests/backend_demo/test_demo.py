"""`cama demo`: a generated site and its proposals loaded once into the backend, demo accounts, then serving."""

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from annotations.schema import AnnotationSet, Georeference, MapElement
from app.backend.config import Settings
from app.backend.main import create_app
from app.backend.models import Element, Site
from cama_pipeline.bev import read_georeference
from cama_studio.cli import app as cli

runner = CliRunner()


def proposals_file(site_dir: Path, path: Path) -> Path:
    """Two proposals in the middle of the site, written as `cama propose` writes them."""
    origin = json.loads((site_dir / "manifest.json").read_text())["config"]["site_origin_xy"]
    georef = Georeference.of(read_georeference(site_dir / "ground_truth" / "bev"), site_origin_xy=origin)
    cx = georef.origin_xy[0] - origin[0] + georef.width * georef.resolution / 2
    cy = georef.origin_xy[1] - origin[1] - georef.height * georef.resolution / 2
    elements = [
        MapElement(
            id=str(i),
            cls="divider",
            points_2d=[(cx + i, cy), (cx + i, cy + 10)],
            source="proposal",
            confidence=0.2 + 0.3 * i,
        )
        for i in range(2)
    ]
    AnnotationSet(site_id="demo", georeference=georef, elements=elements).write_json(path)
    return path


def test_demo_loads_once_and_serves(site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    served: list[object] = []
    monkeypatch.setattr("uvicorn.run", lambda app, **kwargs: served.append(kwargs))
    proposals = proposals_file(site_root, tmp_path / "proposals.json")
    args = ["demo", str(site_root), "--proposals", str(proposals), "--data-dir", str(tmp_path / "server")]
    args += ["--view-port", "0"]
    first = runner.invoke(cli, args)
    assert first.exit_code == 0, first.output
    assert "with 2 proposals" in first.output and "#/site/1" in first.output and "cama-demo" in first.output
    again = runner.invoke(cli, args)
    assert again.exit_code == 0 and "proposals" not in again.output.splitlines()[0]
    assert len(served) == 2 and served[0]["port"] == 8000
    app = create_app(Settings(data_dir=tmp_path / "server"))
    with app.state.sessionmaker() as session:
        assert session.query(Element).count() == 2  # loaded once, not twice
        assert {e.confidence for e in session.query(Element)} == {0.2, 0.5}


def test_demo_names_a_folder_that_is_not_a_site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("uvicorn.run", lambda app, **kwargs: None)
    result = runner.invoke(
        cli, ["demo", str(tmp_path), "--data-dir", str(tmp_path / "server"), "--view-port", "0"]
    )
    assert result.exit_code == 2 and "synthetic_dir" in result.output


def test_demo_shows_a_reconstructed_raster_folder_in_the_proposals_frame(
    site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("uvicorn.run", lambda app, **kwargs: None)
    rasters = tmp_path / "ws" / "surface" / "site-001" / "bev"
    shutil.copytree(site_root / "ground_truth" / "bev", rasters)
    proposals = proposals_file(site_root, tmp_path / "proposals.json")
    args = ["demo", str(site_root), "--proposals", str(proposals), "--rasters", str(rasters)]
    result = runner.invoke(cli, [*args, "--data-dir", str(tmp_path / "server"), "--view-port", "0"])
    assert result.exit_code == 0, result.output
    app = create_app(Settings(data_dir=tmp_path / "server"))
    with app.state.sessionmaker() as session:
        site = session.query(Site).one()
        assert site.name.endswith("(reconstructed)") and Path(site.raster_dir) == rasters.resolve()
        expected = AnnotationSet.read_json(proposals).georeference.site_origin_xy
        assert (site.site_origin_x, site.site_origin_y) == pytest.approx(expected)
    broken = runner.invoke(
        cli, ["demo", str(site_root), "--rasters", str(tmp_path), "--data-dir", str(tmp_path / "s2")]
    )
    assert broken.exit_code == 2 and "georeference.json" in broken.output


def test_demo_links_the_editor_to_its_3d_review(
    site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    served: list[Settings] = []
    monkeypatch.setattr("uvicorn.run", lambda app, **kwargs: served.append(app.state.settings))
    monkeypatch.setattr("app.demo._start_review", lambda *args: None)
    args = ["demo", str(site_root), "--data-dir", str(tmp_path / "server"), "--view-port", "8091"]
    assert runner.invoke(cli, args).exit_code == 0
    assert runner.invoke(cli, [*args, "--host", "0.0.0.0"]).exit_code == 0
    assert runner.invoke(cli, [*args[:-1], "0"]).exit_code == 0
    assert [(s.review_url, s.review_site_id) for s in served] == [
        ("http://127.0.0.1:8091/", 1),
        (":8091", 1),  # every address: the link takes the host the browser used
        ("", None),
    ]


def test_demo_reads_the_cama_settings_and_adds_its_site_to_the_data_roots(
    site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    served: list[Settings] = []
    monkeypatch.setattr("uvicorn.run", lambda app, **kwargs: served.append(app.state.settings))
    monkeypatch.setenv("CAMA_EXTENT_MARGIN_M", "7.5")
    monkeypatch.setenv("CAMA_TOKEN_TTL_S", "600")
    monkeypatch.setenv("CAMA_DATA_ROOTS", str(tmp_path / "shared"))
    args = ["demo", str(site_root), "--data-dir", str(tmp_path / "server"), "--view-port", "0"]
    result = runner.invoke(cli, args)
    assert result.exit_code == 0, result.output
    (settings,) = served
    assert (settings.extent_margin_m, settings.token_ttl_s) == (7.5, 600)
    assert settings.allowed_data_roots == ((tmp_path / "shared").resolve(), site_root.resolve())
    monkeypatch.setenv("CAMA_TOKEN_TTL_S", "-1")
    refused = runner.invoke(cli, args)
    assert refused.exit_code == 2 and "CAMA_TOKEN_TTL_S" in refused.output
