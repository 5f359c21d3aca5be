"""A throwaway in-process backend for the simulated annotator's benchmarks: an admin and an annotator session
on a fresh SQLite database, synthetic sites registered, proposal files loaded (the ground truth they work
towards: `app.review_effort.truth`)."""

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from annotations.schema import AnnotationSet
from app.backend.config import Settings
from app.backend.main import create_app
from app.simulation.annotator import ApiSession

_PASSWORD = "simulated-annotator"


@contextmanager
def local_backend(*data_roots: Path) -> Iterator[tuple[ApiSession, ApiSession]]:
    """(admin, annotator) sessions on a backend app that lives as long as the context; the sites it registers
    must lie in `data_roots`."""
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(
            data_dir=Path(tmp),
            data_roots=(Path(tmp), *data_roots),
            scrypt_n=2**4,
            admin_username="admin",
            admin_password=_PASSWORD,
        )
        with TestClient(create_app(settings)) as client:
            admin = ApiSession(client, "admin", _PASSWORD)
            user = {"username": "sim", "password": _PASSWORD, "role": "annotator"}
            admin.call("POST", "/api/users", json=user)
            yield admin, ApiSession(client, "sim", _PASSWORD)
            client.app.state.engine.dispose()  # type: ignore[attr-defined]


def register_synthetic_site(admin: ApiSession, site: Path, name: str) -> int:
    """Register a synthetic site folder; its backend id."""
    body = {"name": name, "synthetic_dir": str(Path(site).resolve())}
    return int(admin.call("POST", "/api/sites", json=body)["id"])


def site_origin(session: ApiSession, site_id: int) -> np.ndarray:
    return np.asarray(session.call("GET", f"/api/sites/{site_id}")["site_origin_xy"], dtype=np.float64)


def load_proposals(admin: ApiSession, site_id: int, path: Path) -> int:
    """Bulk-load a proposals file, moving its points from the file's site frame to the backend site's."""
    proposals = AnnotationSet.read_json(path)
    shift = np.asarray(proposals.georeference.site_origin_xy, float) - site_origin(admin, site_id)
    elements = [
        {
            "class": e.cls,
            "points": (np.asarray(e.points_2d) + shift).tolist(),
            "confidence": e.confidence,
            "source": "proposal",
        }
        for e in proposals.elements
    ]
    if elements:
        admin.call("POST", f"/api/sites/{site_id}/elements/bulk", json={"elements": elements})
    return len(elements)


def kept_map(session: ApiSession, site_id: int) -> list[tuple[str, np.ndarray]]:
    """(class, global 2D points) of every element not rejected: the site's map after review."""
    origin = site_origin(session, site_id)
    elements = session.call("GET", f"/api/sites/{site_id}/elements")
    return [
        (e["class"], np.asarray(e["points"], float) + origin) for e in elements if e["state"] != "rejected"
    ]
