"""The probe's bad-input battery (issue 21, points 4 and 5): each request gets a 4xx, never a 5xx; no answer
echoes a password or names a filesystem path the caller did not give inside the data roots.

The app runs in process on a temporary SQLite database whose data root is the test's folder; `/etc`, `/proc` and
`/root` lie outside it.
"""

import json
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend import data_roots
from app.backend.config import Settings
from app.backend.main import create_app
from tests.backend_system.system_helpers import ADMIN, GEOREFERENCE, ORIGIN_XY, PASSWORD, divider_points

SECRET = "hunter2-Secret-Pw"
"""The password the login cases send: it must never come back."""
TOO_BIG = 2**64
PATH_WORDS = re.compile(r"/etc|/proc|/root|\.ssh|passwd|subfolders|No such file|Permission denied")
"""Signs of a server path or folder listing in an answer."""
JSON = {"content-type": "application/json"}


@dataclass(frozen=True)
class Case:
    """One bad request."""

    name: str
    method: str
    path: str
    body: bytes | None = None
    headers: dict[str, str] = field(default_factory=dict)
    as_lead: bool = True


@dataclass(frozen=True)
class Seeded:
    """A client of the app (server errors answered as 500, not raised), a lead's headers, a site, an element
    and the data root."""

    client: TestClient
    lead: dict[str, str]
    site_id: int
    element_id: int
    root: Path


@pytest.fixture(scope="module")
def seeded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Seeded]:
    root = tmp_path_factory.mktemp("bad-input").resolve()
    settings = Settings(
        data_dir=root / "data",
        data_roots=(root,),
        scrypt_n=2**4,
        admin_username=ADMIN,
        admin_password=PASSWORD,
        login_max_failures=10_000,  # the battery sends many failing logins from one address
        login_max_failures_per_address=10_000,
    )
    app = create_app(settings)
    raster_dir = root / "bev"
    raster_dir.mkdir()
    (raster_dir / "georeference.json").write_text(json.dumps(GEOREFERENCE))
    (root / "not-a-dataset").mkdir()
    (root / "escape").symlink_to("/etc")
    with TestClient(app, raise_server_exceptions=False) as client:
        token = client.post("/api/auth/login", json={"username": ADMIN, "password": PASSWORD}).json()
        lead = {"Authorization": f"Bearer {token['access_token']}"}
        site = {
            "name": "s",
            "site_origin_xy": ORIGIN_XY,
            "georeference": GEOREFERENCE,
            "raster_dir": str(raster_dir),
        }
        site_id = client.post("/api/sites", json=site, headers=lead).json()["id"]
        element = {"class": "divider", "points": divider_points(5.0, 5.0)}
        element_id = client.post(f"/api/sites/{site_id}/elements", json=element, headers=lead).json()["id"]
        yield Seeded(client, lead, site_id, element_id, root)
    app.state.engine.dispose()


def _json(value: Any) -> bytes:
    return json.dumps(value).encode()


def _site_body(**fields: Any) -> dict[str, Any]:
    return {"name": "p", "site_origin_xy": ORIGIN_XY, "georeference": GEOREFERENCE, **fields}


def login_cases() -> list[Case]:
    """The login requests: deep nesting, lone surrogates, and invalid bodies carrying the password."""
    login = "/api/auth/login"
    return [
        Case("login nested [ x 100000", "POST", login, b"[" * 100_000, JSON, as_lead=False),
        Case(
            "login nested {} x 100000", "POST", login, b'{"a":' * 100_000 + b"1" + b"}" * 100_000, JSON, False
        ),
        Case("login surrogate user", "POST", login, b'{"username": "\\ud800", "password": "x"}', JSON, False),
        Case(
            "login surrogate password",
            "POST",
            login,
            b'{"username": "root", "password": "\\udfff"}',
            JSON,
            False,
        ),
        Case(
            "login surrogate user too long",
            "POST",
            login,
            b'{"username": "' + b"\\ud83d" * 70 + b'", "password": "' + SECRET.encode() + b'"}',
            JSON,
            False,
        ),
        Case(
            "login extra field",
            "POST",
            login,
            _json({"username": "root", "password": SECRET, "x": 1}),
            JSON,
            False,
        ),
        Case("login empty user", "POST", login, _json({"username": "", "password": SECRET}), JSON, False),
        Case(
            "login user too long",
            "POST",
            login,
            _json({"username": "u" * 65, "password": SECRET}),
            JSON,
            False,
        ),
        Case(
            "login password too long",
            "POST",
            login,
            _json({"username": "root", "password": SECRET * 100}),
            JSON,
            False,
        ),
        Case(
            "login password a number",
            "POST",
            login,
            _json({"username": SECRET, "password": 12345}),
            JSON,
            False,
        ),
        Case("login list body", "POST", login, _json([SECRET, SECRET]), JSON, False),
        Case(
            "login form bad utf-8",
            "POST",
            login,
            b"username=root&password=" + SECRET.encode() + b"\xff",
            {"content-type": "application/x-www-form-urlencoded"},
            False,
        ),
    ]


def id_cases(site_id: int, element_id: int) -> list[Case]:
    """Integers past the database's range in bodies and paths, and deep nesting on other routes."""
    element = f"/api/sites/{site_id}/elements/{element_id}"
    return [
        Case(
            "issue element_id 2**64",
            "POST",
            f"/api/sites/{site_id}/issues",
            _json({"reason": "other", "comment": "c", "element_id": TOO_BIG}),
            JSON,
        ),
        Case(
            "element version 2**64",
            "PATCH",
            element,
            _json({"version": TOO_BIG, "points": divider_points(6.0, 6.0)}),
            JSON,
        ),
        Case(
            "review version 2**64",
            "POST",
            f"{element}/review",
            _json({"state": "accepted", "version": TOO_BIG}),
            JSON,
        ),
        Case("site id 2**64", "GET", f"/api/sites/{TOO_BIG}"),
        Case("element id 2**64", "GET", f"/api/sites/{site_id}/elements/{TOO_BIG}"),
        Case("issues element filter 2**64", "GET", f"/api/sites/{site_id}/issues?element_id={TOO_BIG}"),
        Case("sites nested [ x 100000", "POST", "/api/sites", b"[" * 100_000, JSON),
        Case(
            "elements nested [] x 5000",
            "POST",
            f"/api/sites/{site_id}/elements",
            b"[" * 5000 + b"]" * 5000,
            JSON,
        ),
        Case("site name surrogate", "POST", "/api/sites", b'{"name": "\\ud800", "synthetic_dir": "x"}', JSON),
        Case(
            "issue comment surrogate",
            "POST",
            f"/api/sites/{site_id}/issues",
            b'{"reason": "other", "comment": "\\udc00", "point": [1, 1]}',
            JSON,
        ),
        Case(
            "job params surrogate key",
            "POST",
            f"/api/sites/{site_id}/jobs",
            b'{"kind": "lift", "params": {"\\ud800": 1}}',
            JSON,
        ),
    ]


def path_cases(site_id: int, root: Path) -> list[Case]:
    """Server paths outside the data roots, missing, not folders, or escaping by `..` or a symlink."""
    jobs = f"/api/sites/{site_id}/jobs"
    outside = [
        "/etc",
        "/root/.ssh",
        "../../../proc/self",
        str(root / ".." / ".." / "etc"),
        str(root / "escape"),
    ]
    cases = []
    for index, folder in enumerate(
        [*outside, str(root / "missing"), str(root / "bev" / "georeference.json")]
    ):
        cases.append(
            Case(
                f"raster_dir {folder}",
                "POST",
                "/api/sites",
                _json(_site_body(name=f"r{index}", raster_dir=folder)),
                JSON,
            )
        )
        cases.append(
            Case(
                f"synthetic_dir {folder}",
                "POST",
                "/api/sites",
                _json({"name": f"s{index}", "synthetic_dir": folder}),
                JSON,
            )
        )
        export = {"kind": "export", "params": {"format": "maptr", "dataset_root": folder}}
        cases.append(Case(f"dataset_root {folder}", "POST", jobs, _json(export), JSON))
    return cases


def send(seeded: Seeded, case: Case) -> tuple[int, str]:
    headers = {**case.headers, **(seeded.lead if case.as_lead else {})}
    response = seeded.client.request(case.method, case.path, content=case.body, headers=headers)
    return response.status_code, response.text


def all_cases(seeded: Seeded) -> list[Case]:
    return [
        *login_cases(),
        *id_cases(seeded.site_id, seeded.element_id),
        *path_cases(seeded.site_id, seeded.root),
    ]


def test_battery_answers_4xx_without_echoing_secrets_or_paths(seeded: Seeded) -> None:
    answers = {case.name: send(seeded, case) for case in all_cases(seeded)}
    server_errors = {name: code for name, (code, _text) in answers.items() if code >= 500}
    print(f"bad-input battery: {len(answers)} requests, {len(server_errors)} 5xx")
    assert not server_errors, server_errors
    assert all(400 <= code < 500 for code, _text in answers.values()), answers
    echoed = [name for name, (_code, text) in answers.items() if SECRET in text or "12345" in text]
    assert not echoed, echoed
    disclosed = [
        name for name, (_code, text) in answers.items() if PATH_WORDS.search(text) or str(seeded.root) in text
    ]
    assert not disclosed, {name: answers[name] for name in disclosed}


def test_refused_folders_all_get_the_same_answer(seeded: Seeded, monkeypatch: pytest.MonkeyPatch) -> None:
    """Missing, outside the roots, a file, a symlink out, and unreadable (as root every folder is readable, so
    `os.access` is made to say no) read the same."""

    def refusal(folder: str) -> Any:
        body = _site_body(name="same", raster_dir=folder)
        response = seeded.client.post("/api/sites", json=body, headers=seeded.lead)
        assert response.status_code == 422, response.text
        return response.json()

    answers = [
        refusal(folder) for folder in ("/etc", str(seeded.root / "missing"), str(seeded.root / "escape"))
    ]
    (seeded.root / "locked").mkdir()
    monkeypatch.setattr(data_roots.os, "access", lambda *_args: False)
    answers.append(refusal(str(seeded.root / "locked")))
    assert all(answer == answers[0] for answer in answers), answers


def test_export_of_a_folder_inside_the_roots_that_is_no_data_set_fails_without_listing_it(
    seeded: Seeded,
) -> None:
    export = {
        "kind": "export",
        "params": {"format": "maptr", "poses": "coarse", "dataset_root": str(seeded.root / "not-a-dataset")},
    }
    job = seeded.client.post(f"/api/sites/{seeded.site_id}/jobs", json=export, headers=seeded.lead)
    assert job.status_code == 202, job.text
    deadline = time.monotonic() + 10.0
    while (state := seeded.client.get(f"/api/jobs/{job.json()['id']}", headers=seeded.lead).json())[
        "state"
    ] in (
        "queued",
        "running",
    ):
        assert time.monotonic() < deadline, state
        time.sleep(0.02)
    assert state["state"] == "failed" and "dataset_root" in state["message"], state
    assert str(seeded.root) not in state["message"] and "subfolders" not in state["message"], state
