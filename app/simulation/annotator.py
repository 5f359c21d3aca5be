"""The scripted annotator over HTTP: leases items from the backend's annotator queue, accepts, fixes or rejects
each proposal as `app.review_effort.plan.decide` says, draws what nobody proposed, and books the time every action
would take (`app.review_effort.session.work_queue`, on the backend's queue).

Two workflows are measured on the same site and truth: correcting proposals (`correct_proposals`) and drawing
everything from an empty site (`draw_from_scratch`). Time per km of road compares them (the paper's claim that
correcting VMA proposals is more than twice as fast as drawing).
"""

import logging
from collections.abc import Sequence
from typing import Any

import httpx
import numpy as np

from app.review_effort import session as review
from app.review_effort.costs import ActionCosts
from app.review_effort.plan import Decision, Polyline, SimulationConfig, clicked_vertices
from app.review_effort.session import SessionLog

logger = logging.getLogger(__name__)


class SimulationError(RuntimeError):
    """The backend refused a request the annotator needs; names the request and the answer."""


class ApiSession:
    """A logged-in user of the backend's HTTP API (any httpx client: a live server or an in-process app)."""

    def __init__(self, client: httpx.Client, username: str, password: str) -> None:
        self.client = client
        token = self._call("POST", "/api/auth/login", json={"username": username, "password": password})
        self.headers = {"Authorization": f"Bearer {token['access_token']}"}

    def _call(self, method: str, url: str, **kwargs: Any) -> Any:
        response = self.client.request(method, url, headers=getattr(self, "headers", {}), **kwargs)
        if response.status_code == 204:
            return None
        if response.status_code >= 400:
            raise SimulationError(f"{method} {url}: HTTP {response.status_code}: {response.text[:300]}")
        return response.json()

    def call(self, method: str, url: str, **kwargs: Any) -> Any:
        """One request; the JSON answer, None for 204, SimulationError for an error status."""
        return self._call(method, url, **kwargs)


def _site_truths(session: ApiSession, site_id: int, truths_global: Sequence[Polyline]) -> list[Polyline]:
    """The true elements in the site's frame (site = global - site_origin_xy)."""
    origin = np.asarray(session.call("GET", f"/api/sites/{site_id}")["site_origin_xy"], dtype=np.float64)
    return [Polyline(t.cls, np.asarray(t.points, dtype=np.float64)[:, :2] - origin) for t in truths_global]


class HttpQueue:
    """A backend site's annotator queue as a `review_effort.session.ReviewQueue`: items are element dicts."""

    def __init__(self, session: ApiSession, site_id: int) -> None:
        self.session = session
        self.site_id = site_id

    def next(self) -> dict[str, Any] | None:
        lease = self.session.call("POST", f"/api/sites/{self.site_id}/queue/next")
        return None if lease is None else dict(lease["element"])

    def polyline(self, item: dict[str, Any]) -> Polyline:
        return Polyline(item["class"], np.asarray(item["points"], float))

    def pending(self, item: dict[str, Any]) -> list[dict[str, Any]]:
        """The other proposals still waiting for a verdict: what the annotator sees around the leased one."""
        elements = self.session.call(
            "GET", f"/api/sites/{self.site_id}/elements", params={"state": "proposed"}
        )
        return [e for e in elements if e["id"] != item["id"]]

    def apply(self, item: dict[str, Any], decision: Decision, pending: Sequence[dict[str, Any]]) -> None:
        """A fix deletes the pieces merged into it (as the editor's merge does), PATCHes the points and gives the
        `fixed` verdict; accept and reject are verdicts. A split keeps the first part in the element and creates
        the second as a new one (as the editor's split does), accepted with its corrected points."""
        base = f"/api/sites/{self.site_id}/elements/{item['id']}"
        version = int(item["version"])
        for k in decision.merged:
            piece = pending[k]
            self.session.call(
                "DELETE",
                f"/api/sites/{self.site_id}/elements/{piece['id']}",
                params={"version": piece["version"]},
            )
        if decision.kind == "fix":
            body: dict[str, Any] = {"version": version, "points": np.asarray(decision.points).tolist()}
            if decision.relabel:
                body["class"] = decision.relabel
            version = int(self.session.call("PATCH", base, json=body)["version"])
        verdict = {"accept": "accepted", "fix": "fixed", "reject": "rejected"}[decision.kind]
        self.session.call("POST", f"{base}/review", json={"state": verdict, "version": version})
        if decision.split_off is not None:
            self._create_accepted(item["class"], np.asarray(decision.split_off.points).tolist())

    def draw(self, truth: Polyline, config: SimulationConfig) -> None:
        """Draw a new element and give it the `accepted` verdict, as the editor's draw-then-accept does."""
        self._create_accepted(truth.cls, clicked_vertices(truth, config).tolist())

    def _create_accepted(self, cls: str, points: list[list[float]]) -> None:
        """A new element made by the annotator, with the `accepted` verdict."""
        body = {"class": cls, "points": points, "source": "human"}
        element = self.session.call("POST", f"/api/sites/{self.site_id}/elements", json=body)
        verdict = {"state": "accepted", "version": int(element["version"])}
        self.session.call("POST", f"/api/sites/{self.site_id}/elements/{element['id']}/review", json=verdict)


def correct_proposals(
    session: ApiSession,
    site_id: int,
    truths_global: Sequence[Polyline],
    *,
    config: SimulationConfig | None = None,
    costs: ActionCosts | None = None,
    max_items: int = 100_000,
) -> SessionLog:
    """Work the annotator queue until it is empty, then draw the true elements no proposal covered."""
    config, costs = config or SimulationConfig(), costs or ActionCosts()
    truths = _site_truths(session, site_id, truths_global)
    try:
        return review.work_queue(HttpQueue(session, site_id), truths, config, costs, max_items=max_items)
    except review.UnfinishedQueue as error:
        raise SimulationError(f"site {site_id}: {error}") from None


def draw_from_scratch(
    session: ApiSession,
    site_id: int,
    truths_global: Sequence[Polyline],
    *,
    config: SimulationConfig | None = None,
    costs: ActionCosts | None = None,
) -> SessionLog:
    """Draw every true element on a site that has no proposals."""
    config, costs = config or SimulationConfig(), costs or ActionCosts()
    truths = _site_truths(session, site_id, truths_global)
    return review.draw_from_scratch(HttpQueue(session, site_id), truths, config, costs)
