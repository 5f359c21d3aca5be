"""Where the 3D view reads vectors from: an annotation file (`AnnotationSet` JSON) or the running backend.

Both give the same `ViewElement`s in global metres (the source adds its site origin), so the scene does not care
which, nor which origin the site's annotations were made in.
"""

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import httpx
import numpy as np

from annotations.schema import POLYGON_CLASSES, AnnotationSet

logger = logging.getLogger(__name__)


class VectorSourceError(ValueError):
    """The vectors could not be read; names the file or URL and what was wrong."""


@dataclass(frozen=True, eq=False)
class ViewElement:
    """One vector as the 3D view needs it."""

    id: str
    cls: str
    state: str
    version: int
    points_xy: np.ndarray
    """(N, 2) global metres."""

    @property
    def closed(self) -> bool:
        """A crosswalk is a polygon ring."""
        return self.cls in POLYGON_CLASSES

    @property
    def key(self) -> tuple[str, int, str, str]:
        """What must change for the view to redraw the element."""
        return self.id, self.version, self.state, self.cls


class VectorSource(Protocol):
    """Anything that lists a site's current vectors."""

    def load(self) -> list[ViewElement]: ...


@dataclass(frozen=True)
class FileVectorSource:
    """An `AnnotationSet` JSON file (e.g. `cama propose` output), re-read on every load."""

    path: Path

    def load(self) -> list[ViewElement]:
        try:
            annotations = AnnotationSet.read_json(self.path)
        except (OSError, ValueError) as err:
            raise VectorSourceError(f"{self.path}: cannot read annotations: {err}") from None
        origin = np.asarray(annotations.georeference.site_origin_xy, dtype=np.float64)
        return [
            ViewElement(
                e.id, e.cls, e.review_state, e.version, np.asarray(e.points_2d, dtype=np.float64) + origin
            )
            for e in annotations.elements
        ]


class ApiVectorSource:
    """A site's elements from the backend (`GET /sites/{id}/elements`), logged in once with a user's password."""

    def __init__(self, base_url: str, site_id: int, username: str, password: str, *, timeout_s: float = 10.0):
        self._client = httpx.Client(base_url=base_url.rstrip("/"), timeout=timeout_s)
        self._site_id = site_id
        self._credentials = {"username": username, "password": password}
        self._token: str | None = None
        self._site_origin_xy: np.ndarray | None = None

    def _login(self) -> str:
        response = self._request("POST", "/api/auth/login", json=self._credentials, with_token=False)
        return str(response.json()["access_token"])

    def _request(
        self, method: str, path: str, *, with_token: bool = True, **kwargs: object
    ) -> httpx.Response:
        headers = {"Authorization": f"Bearer {self._token}"} if with_token and self._token else {}
        url = f"{self._client.base_url}{path}"
        try:
            response = self._client.request(method, path, headers=headers, **kwargs)  # type: ignore[arg-type]
        except httpx.HTTPError as err:
            raise VectorSourceError(f"{url}: backend not reachable: {err}") from None
        if response.status_code == 401 and with_token:
            self._token = None  # expired: the next load logs in again
        if response.status_code >= 400:
            raise VectorSourceError(f"{url}: HTTP {response.status_code}: {response.text[:200]}")
        return response

    def load(self) -> list[ViewElement]:
        if self._token is None:
            self._token = self._login()
        if self._site_origin_xy is None:
            site = self._request("GET", f"/api/sites/{self._site_id}").json()
            self._site_origin_xy = np.asarray(site["site_origin_xy"], dtype=np.float64)
        response = self._request("GET", f"/api/sites/{self._site_id}/elements", params={"limit": 100_000})
        origin = self._site_origin_xy
        return [
            ViewElement(
                str(e["id"]),
                e["class"],
                e["state"],
                int(e["version"]),
                np.asarray(e["points"], float) + origin,
            )
            for e in response.json()
        ]

    def close(self) -> None:
        """Close the HTTP connection pool."""
        self._client.close()
