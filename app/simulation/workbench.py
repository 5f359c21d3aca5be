"""A throwaway in-process backend for the simulated annotator's benchmarks: an admin and an annotator session
on a fresh SQLite database, synthetic sites registered, proposal files loaded, ground truth read."""

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
from app.simulation.plan import Polyline
from cama_pipeline.evaluate.inputs import load_vector_map
from cama_pipeline.evaluate.observed import ObservedMask, observed_parts
from models.vma.rasters import load_site_rasters

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


def true_polylines(site: Path) -> list[Polyline]:
    """The generator's true vectors of a synthetic site (global metres, 2D)."""
    elements = load_vector_map(Path(site) / "ground_truth" / "vector_map.json")
    return [Polyline(e.cls, np.asarray(e.points)[:, :2]) for e in elements]


def observed_true_polylines(site: Path, rasters_folder: Path) -> list[Polyline]:
    """The site's true vectors cut to the cells a reconstruction's rasters observed (nobody draws road that no
    camera saw)."""
    rasters = load_site_rasters(rasters_folder)
    mask = ObservedMask.from_semantic(rasters.semantic, rasters.origin_xy, rasters.resolution_m)
    return [
        Polyline(t.cls, part)
        for t in true_polylines(site)
        for part in observed_parts(t.points, t.closed, mask)
    ]


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
