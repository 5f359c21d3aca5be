"""Property-based fuzzing of the OpenAPI schema with schemathesis: no 5xx, responses conform to the schema.

The app runs in process (ASGI) on a temporary SQLite database seeded with a site and elements; every generated
request carries a lead's token, so authenticated paths are exercised past the role checks.
"""

import json
import re
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.backend.config import Settings
from app.backend.main import create_app
from tests.backend_system.system_helpers import ADMIN, GEOREFERENCE, ORIGIN_XY, PASSWORD, divider_points
from tests.dependency_policy import require_module

schemathesis = require_module("schemathesis")

MAX_EXAMPLES = 25
"""Examples per operation; about 20 operations keep the run well under a minute."""
CHECKS = [
    schemathesis.checks.not_a_server_error,
    schemathesis.checks.response_schema_conformance,
    schemathesis.checks.content_type_conformance,
]

SQLITE_INT_MAX = 2**63 - 1
PROPERTY_EXAMPLES = 30
"""Examples per hand-written property below (derandomized, like the schema fuzz)."""
PROPERTY_SETTINGS = settings(
    max_examples=PROPERTY_EXAMPLES,
    deadline=None,
    database=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def text_with_lone_surrogates() -> st.SearchStrategy[str]:
    """Strings with at least one lone surrogate (U+D800..U+DFFF alone), which JSON carries as `\\udXXX`
    escapes and Python decodes into a str that cannot be encoded to UTF-8. `st.text` itself never draws
    surrogates, so the inserted ones stay lone."""
    lone = st.characters(min_codepoint=0xD800, max_codepoint=0xDFFF)
    return st.tuples(st.text(max_size=12), st.lists(lone, min_size=1, max_size=3), st.text(max_size=12)).map(
        lambda parts: parts[0] + "".join(parts[1]) + parts[2]
    )


def deeply_nested_json() -> st.SearchStrategy[bytes]:
    """JSON bodies nested far deeper than any real request (1,000 to 200,000 levels of arrays, objects or
    both), closed or left open."""
    opener = st.sampled_from([(b"[", b"]"), (b'{"a":', b"}"), (b'[{"a":', b"}]")])
    return st.builds(
        lambda depth, brackets, closed: brackets[0] * depth + (b"1" + brackets[1] * depth if closed else b""),
        st.integers(min_value=1_000, max_value=200_000),
        opener,
        st.booleans(),
    )


@pytest.fixture(scope="module")
def fuzz_app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[FastAPI, dict[str, str]]]:
    """The app on a seeded database, and a lead's auth headers."""
    root = tmp_path_factory.mktemp("fuzz")
    app = create_app(
        Settings(
            data_dir=root / "data",
            data_roots=(root,),
            scrypt_n=2**4,
            admin_username=ADMIN,
            admin_password=PASSWORD,
        )
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
    app, _lead = fuzz_app
    with TestClient(app) as client:  # a token of its own: the fuzzed logout revokes it
        token = client.post("/api/auth/login", json={"username": "lead", "password": PASSWORD}).json()
    lead = {"Authorization": f"Bearer {token['access_token']}"}
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    operations = [result.ok() for result in schema.get_all_operations()]
    operations.sort(
        key=lambda operation: operation.path == "/api/auth/logout"
    )  # last: the rest stays signed in
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


def test_lone_surrogates_in_login_are_4xx_and_never_echo_the_password(
    fuzz_app: tuple[FastAPI, dict[str, str]],
) -> None:
    app, _lead = fuzz_app
    with TestClient(app, raise_server_exceptions=False) as client:

        @PROPERTY_SETTINGS
        @given(
            username=st.one_of(st.just(ADMIN), text_with_lone_surrogates()),
            password=text_with_lone_surrogates(),
        )
        def login(username: str, password: str) -> None:
            body = json.dumps({"username": username, "password": password}).encode()  # ASCII: \\udXXX escapes
            response = client.post(
                "/api/auth/login", content=body, headers={"content-type": "application/json"}
            )
            assert 400 <= response.status_code < 500, response.text
            assert json.dumps(password)[1:-1] not in response.text

        login()


def test_lone_surrogates_in_other_text_fields_are_4xx(fuzz_app: tuple[FastAPI, dict[str, str]]) -> None:
    app, lead = fuzz_app
    with TestClient(app, raise_server_exceptions=False) as client:
        site_id = client.get("/api/sites", headers=lead).json()[0]["id"]

        @PROPERTY_SETTINGS
        @given(text=text_with_lone_surrogates())
        def post(text: str) -> None:
            bodies = {
                "/api/sites": {"name": text, "synthetic_dir": text},
                f"/api/sites/{site_id}/issues": {"reason": "other", "comment": text, "point": [1.0, 1.0]},
                f"/api/sites/{site_id}/jobs": {"kind": "export", "params": {"dataset_root": text, text: 1}},
                "/api/users": {"username": text, "password": text},
            }
            for path, body in bodies.items():
                response = client.post(
                    path,
                    content=json.dumps(body).encode(),
                    headers={**lead, "content-type": "application/json"},
                )
                assert 400 <= response.status_code < 500, (path, response.text)

        post()


def test_deeply_nested_bodies_are_4xx(fuzz_app: tuple[FastAPI, dict[str, str]]) -> None:
    app, lead = fuzz_app
    with TestClient(app, raise_server_exceptions=False) as client:
        site_id = client.get("/api/sites", headers=lead).json()[0]["id"]
        paths = [
            "/api/auth/login",
            "/api/sites",
            f"/api/sites/{site_id}/elements",
            f"/api/sites/{site_id}/jobs",
        ]

        @PROPERTY_SETTINGS
        @given(body=deeply_nested_json(), path=st.sampled_from(paths))
        def post(body: bytes, path: str) -> None:
            response = client.post(path, content=body, headers={**lead, "content-type": "application/json"})
            assert 400 <= response.status_code < 500, (path, response.text[:200])

        post()


def test_issue_element_id_beyond_int64_is_422(fuzz_app: tuple[FastAPI, dict[str, str]]) -> None:
    app, lead = fuzz_app
    with TestClient(app, raise_server_exceptions=False) as client:
        site_id = client.get("/api/sites", headers=lead).json()[0]["id"]
        body = {"reason": "other", "comment": "c", "element_id": 2**64}
        response = client.post(f"/api/sites/{site_id}/issues", json=body, headers=lead)
    assert response.status_code == 422, response.text
