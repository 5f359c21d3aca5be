"""Where the 3D view reads vectors from: an annotation file (`AnnotationSet` JSON) or the running backend.

Both give the same `ViewElement`s in global metres (the source adds its site origin), so the scene does not care
which, nor which origin the site's annotations were made in. A source is read in full once (`load`), then asked
what changed since (`changes`): the file when its modification time moves, the backend through its changes
cursor, so an idle poll moves no element data.
"""

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import httpx
import numpy as np

from annotations.schema import POLYGON_CLASSES, AnnotationSet
from app.backend.poll_log import quiet_change_polls

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


@dataclass(frozen=True)
class VectorChanges:
    """What changed in a source since it was last read."""

    elements: list[ViewElement]
    """New or changed elements; every element when `complete`."""
    removed: list[str] = field(default_factory=list)
    """Ids of elements gone."""
    complete: bool = False
    """`elements` is the whole set: anything not in it is gone."""


class VectorSource(Protocol):
    """Anything that lists a site's current vectors, and what changed since its last read."""

    def load(self) -> list[ViewElement]: ...

    def changes(self) -> VectorChanges: ...


class FileVectorSource:
    """An `AnnotationSet` JSON file (e.g. `cama propose` output): `load` reads it, `changes` reads it again only
    when its modification time or size moved."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._stamp: tuple[int, int] | None = None

    def _stat(self) -> tuple[int, int]:
        try:
            stat = self.path.stat()
        except OSError as err:
            raise VectorSourceError(f"{self.path}: cannot read annotations: {err}") from None
        return stat.st_mtime_ns, stat.st_size

    def changes(self) -> VectorChanges:
        if self._stamp is not None and self._stat() == self._stamp:
            return VectorChanges([])
        return VectorChanges(self.load(), complete=True)

    def load(self) -> list[ViewElement]:
        stamp = self._stat()
        try:
            annotations = AnnotationSet.read_json(self.path)
        except (OSError, ValueError) as err:
            raise VectorSourceError(f"{self.path}: cannot read annotations: {err}") from None
        self._stamp = stamp
        origin = np.asarray(annotations.georeference.site_origin_xy, dtype=np.float64)
        return [
            ViewElement(
                e.id, e.cls, e.review_state, e.version, np.asarray(e.points_2d, dtype=np.float64) + origin
            )
            for e in annotations.elements
        ]


class ApiVectorSource:
    """A site's elements from the backend, logged in once with a user's password: every element once, then only
    what changed after the last answer's cursor (`GET /sites/{id}/elements/changes?since=`). Its successful
    polls are left out of httpx's request log (`app/backend/poll_log.py`)."""

    def __init__(
        self,
        base_url: str,
        site_id: int,
        username: str,
        password: str,
        *,
        timeout_s: float = 10.0,
        client: httpx.Client | None = None,
    ):
        """`client`: an httpx client to use instead of a new one on `base_url` (e.g. an in-process app's)."""
        self._client = client or httpx.Client(base_url=base_url.rstrip("/"), timeout=timeout_s)
        self._site_id = site_id
        self._credentials = {"username": username, "password": password}
        self._token: str | None = None
        self._site_origin_xy: np.ndarray | None = None
        self._cursor: int | None = None
        quiet_change_polls("httpx")

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

    def _changes_since(self, since: int) -> tuple[list[ViewElement], list[str], int]:
        """(changed elements, deleted ids, cursor) after edit-log id `since`, logging in first when needed."""
        if self._token is None:
            self._token = self._login()
        if self._site_origin_xy is None:
            site = self._request("GET", f"/api/sites/{self._site_id}").json()
            self._site_origin_xy = np.asarray(site["site_origin_xy"], dtype=np.float64)
        path = f"/api/sites/{self._site_id}/elements/changes"
        body = self._request("GET", path, params={"since": since}).json()
        origin = self._site_origin_xy
        elements = [
            ViewElement(
                str(e["id"]),
                e["class"],
                e["state"],
                int(e["version"]),
                np.asarray(e["points"], float) + origin,
            )
            for e in body["elements"]
        ]
        return elements, [str(i) for i in body["deleted"]], int(body["cursor"])

    def load(self) -> list[ViewElement]:
        elements, _, self._cursor = self._changes_since(0)
        return elements

    @property
    def site_id(self) -> int:
        """The backend's site id."""
        return self._site_id

    @property
    def site_origin_xy(self) -> np.ndarray:
        """(2,) global metres of the site's origin (read with the first `load`): API coordinates are relative
        to it in x and y."""
        if self._site_origin_xy is None:
            self.load()
        assert self._site_origin_xy is not None  # set by load
        return self._site_origin_xy

    def get(self, path: str, **params: object) -> httpx.Response:
        """GET another endpoint of the backend (e.g. the camera views of `app/viewer/cameras.py`) as this
        source's user, logging in first when needed; VectorSourceError for a transport failure or an error
        status."""
        if self._token is None:
            self._token = self._login()
        return self._request("GET", path, params=params)

    def changes(self) -> VectorChanges:
        if self._cursor is None:
            return VectorChanges(self.load(), complete=True)
        elements, removed, cursor = self._changes_since(self._cursor)
        if cursor < self._cursor:
            logger.info(
                "the backend's edit log restarted (cursor %d < %d): reading every element",
                cursor,
                self._cursor,
            )
            return VectorChanges(self.load(), complete=True)
        logger.debug("changes after %d: %d elements, %d deleted", self._cursor, len(elements), len(removed))
        self._cursor = cursor
        return VectorChanges(elements, removed)

    def close(self) -> None:
        """Close the HTTP connection pool."""
        self._client.close()
