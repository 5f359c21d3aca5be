"""Property-based fuzzing of the OpenAPI schema with schemathesis: no 5xx, responses conform to the schema.

The app runs in process (ASGI) on a temporary SQLite database seeded with a site and elements; every generated
request carries a lead's token, so authenticated paths are exercised past the role checks.
"""

import json
import re
from collections.abc import Iterator
from typing import Any

import pytest
from dependency_policy import require_module
from fastapi import FastAPI
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from system_helpers import ADMIN, GEOREFERENCE, ORIGIN_XY, PASSWORD, divider_points

from app.backend.config import Settings
from app.backend.main import create_app

schemathesis = require_module("schemathesis")

MAX_EXAMPLES = 25
"""Examples per operation; about 20 operations keep the run well under a minute."""
CHECKS = [
    schemathesis.checks.not_a_server_error,
    schemathesis.checks.response_schema_conformance,
    schemathesis.checks.content_type_conformance,
]

SQLITE_INT_MAX = 2**63 - 1


@pytest.fixture(scope="module")
def fuzz_app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[FastAPI, dict[str, str]]]:
    """The app on a seeded database, and a lead's auth headers."""
    root = tmp_path_factory.mktemp("fuzz")
    app = create_app(
        Settings(data_dir=root / "data", scrypt_n=2**4, admin_username=ADMIN, admin_password=PASSWORD)
    )
    raster_dir = root / "bev"
    raster_dir.mkdir()
    (raster_dir / "georeference.json").write_text(json.dumps(GEOREFERENCE))  # no layer files: tiles are 404
    with TestClient(app) as client:
        token = client.post("/api/auth/login", json={"username": ADMIN, "password": PASSWORD}).json()
        admin = {"Authorization": f"Bearer {token['access_token']}"}
        user = {"username": "lead", "password": PASSWORD, "role": "lead"}
        assert client.post("/api/users", json=user, headers=admin).status_code == 201
        token = client.post("/api/auth/login", json={"username": "lead", "password": PASSWORD}).json()
        lead = {"Authorization": f"Bearer {token['access_token']}"}
        site = {
            "name": "fuzz",
            "site_origin_xy": ORIGIN_XY,
            "georeference": GEOREFERENCE,
            "raster_dir": str(raster_dir),
        }
        site_id = client.post("/api/sites", json=site, headers=lead).json()["id"]
        for index in range(3):
            body = {"class": "divider", "points": divider_points(5.0 + 10 * index, 5.0)}
            assert client.post(f"/api/sites/{site_id}/elements", json=body, headers=lead).status_code == 201
    yield app, lead
    app.state.engine.dispose()


@pytest.mark.slow
def test_openapi_fuzz_no_server_error_and_conforming_responses(
    fuzz_app: tuple[FastAPI, dict[str, str]],
) -> None:
    app, lead = fuzz_app
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) >= 15, [operation.label for operation in operations]
    cases_run = 0

    for operation in operations:

        @given(case=operation.as_strategy())
        @settings(
            max_examples=MAX_EXAMPLES,
            deadline=None,
            suppress_health_check=list(HealthCheck),
            database=None,
            derandomize=True,  # the same cases every run, so CI is reproducible; raise MAX_EXAMPLES to explore
        )
        def fuzz_operation(case: Any) -> None:
            nonlocal cases_run
            cases_run += 1
            case.call_and_validate(headers=lead, checks=CHECKS)

        fuzz_operation()
    print(f"schemathesis: {cases_run} cases over {len(operations)} operations")


def test_path_id_beyond_int64_is_not_a_server_error(fuzz_app: tuple[FastAPI, dict[str, str]]) -> None:
    app, lead = fuzz_app
    with TestClient(app, raise_server_exceptions=False) as client:
        response = client.get(f"/api/sites/{SQLITE_INT_MAX + 1}", headers=lead)
    assert response.status_code < 500, response.text


def test_datetimes_conform_to_openapi_date_time(fuzz_app: tuple[FastAPI, dict[str, str]]) -> None:
    app, lead = fuzz_app
    with TestClient(app) as client:
        site_id = client.get("/api/sites", headers=lead).json()[0]["id"]
        element = client.get(f"/api/sites/{site_id}/elements", headers=lead).json()[0]
    assert re.search(r"(Z|[+-]\d\d:\d\d)$", element["created_at"]), element["created_at"]
