"""Backend test helpers shared by the fixtures and tests: constants, login, element bodies."""

from dataclasses import replace
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from app.backend.config import Settings
from cama_studio.pipeline import PipelineResult
from tests.conftest import GeneratedSite

PASSWORD = "correct horse battery"
ROLES = ("annotator", "lead", "admin")
ORIGIN_XY = (1000.0, 2000.0)
GEOREFERENCE = {"origin_xy": [1000.0, 2100.0], "resolution": 0.5, "width": 200, "height": 200}
"""Site extent in site metres: x [-0.25, 99.75], y [0.25, 100.25]."""


def login(client: TestClient, username: str, password: str = PASSWORD) -> dict[str, str]:
    """Authorization headers for a user."""
    response = client.post("/api/auth/login", json={"username": username, "password": password})
    assert response.status_code == 200, response.text
    return {"Authorization": f"Bearer {response.json()['access_token']}"}


def register_site(client: TestClient, lead: dict[str, str], raster_dir: Path, name: str) -> int:
    """Register the 100 m x 100 m test site on `raster_dir` (as a lead); its id."""
    body = {
        "name": name,
        "site_origin_xy": ORIGIN_XY,
        "georeference": GEOREFERENCE,
        "raster_dir": str(raster_dir),
    }
    response = client.post("/api/sites", json=body, headers=lead)
    assert response.status_code == 201, response.text
    return int(response.json()["id"])


def divider(x0: float = 10.0, y0: float = 10.0, **extra: Any) -> dict[str, Any]:
    """A short divider element body."""
    return {"class": "divider", "points": [[x0, y0], [x0 + 5.0, y0], [x0 + 10.0, y0 + 1.0]], **extra}


def crosswalk(x0: float = 50.0, y0: float = 50.0) -> dict[str, Any]:
    """A closed 4 m x 3 m crosswalk body."""
    ring = [[x0, y0], [x0 + 4, y0], [x0 + 4, y0 + 3], [x0, y0 + 3], [x0, y0]]
    return {"class": "ped_crossing", "points": ring}


def with_reconstruction(settings: Settings, tiny_site: GeneratedSite, whole_path: PipelineResult) -> Settings:
    """The settings with the tiny site's data set and its reconstruction (`whole_path`) inside the data roots."""
    roots = (*settings.data_roots, tiny_site.result.out_dir, whole_path.workspace)
    return replace(settings, data_roots=roots)
