"""The scripted annotator: leases items from the backend's annotator queue over HTTP, accepts, fixes or rejects
each proposal as `plan.decide` says, draws what nobody proposed, and books the time every action would take.

Two workflows are measured on the same site and truth: correcting proposals (`correct_proposals`) and drawing
everything from an empty site (`draw_from_scratch`). Time per km of road compares them (the paper's claim that
correcting VMA proposals is more than twice as fast as drawing).
"""

import logging
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np

from app.simulation.costs import ActionCosts
from app.simulation.plan import (
    Decision,
    Polyline,
    SimulationConfig,
    clicked_vertices,
    decide,
    drawing_seconds,
    road_length_km,
)

logger = logging.getLogger(__name__)


class SimulationError(RuntimeError):
    """The backend refused a request the annotator needs; names the request and the answer."""


@dataclass
class SessionLog:
    """What one simulated session did and the time it would have taken a person."""

    seconds: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    counts: Counter[str] = field(default_factory=Counter)
    road_km: float = 0.0

    @property
    def total_s(self) -> float:
        return float(sum(self.seconds.values()))

    def hours_per_km(self) -> float:
        """Person-hours per km of road."""
        return self.total_s / 3600 / self.road_km if self.road_km > 0 else float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {
            "seconds": dict(self.seconds),
            "counts": dict(self.counts),
            "total_s": self.total_s,
            "road_km": self.road_km,
            "hours_per_km": self.hours_per_km(),
        }


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


def _pending(session: ApiSession, site_id: int, leased: dict[str, Any]) -> list[dict[str, Any]]:
    """The other proposals still waiting for a verdict: what the annotator sees around the leased one."""
    elements = session.call("GET", f"/api/sites/{site_id}/elements", params={"state": "proposed"})
    return [e for e in elements if e["id"] != leased["id"]]


def _as_polyline(element: dict[str, Any]) -> Polyline:
    return Polyline(element["class"], np.asarray(element["points"], float))


def _apply(
    session: ApiSession,
    site_id: int,
    element: dict[str, Any],
    decision: Decision,
    pending: Sequence[dict[str, Any]],
) -> None:
    """Send one decision: a fix deletes the pieces merged into it (as the editor's merge does), PATCHes the
    points and gives the `fixed` verdict; accept and reject are verdicts."""
    base = f"/api/sites/{site_id}/elements/{element['id']}"
    version = int(element["version"])
    for k in decision.merged:
        piece = pending[k]
        session.call(
            "DELETE", f"/api/sites/{site_id}/elements/{piece['id']}", params={"version": piece["version"]}
        )
    if decision.kind == "fix":
        body: dict[str, Any] = {"version": version, "points": np.asarray(decision.points).tolist()}
        if decision.relabel:
            body["class"] = decision.relabel
        version = int(session.call("PATCH", base, json=body)["version"])
    verdict = {"accept": "accepted", "fix": "fixed", "reject": "rejected"}[decision.kind]
    session.call("POST", f"{base}/review", json={"state": verdict, "version": version})


def _draw(session: ApiSession, site_id: int, truth: Polyline, config: SimulationConfig) -> None:
    """Draw a new element and give it the `accepted` verdict, as the editor's draw-then-accept does."""
    points = clicked_vertices(truth, config).tolist()
    body = {"class": truth.cls, "points": points, "source": "human"}
    element = session.call("POST", f"/api/sites/{site_id}/elements", json=body)
    review = {"state": "accepted", "version": int(element["version"])}
    session.call("POST", f"/api/sites/{site_id}/elements/{element['id']}/review", json=review)


def _book_drawing(
    log: SessionLog,
    session: ApiSession,
    site_id: int,
    truths: Sequence[Polyline],
    config: SimulationConfig,
    costs: ActionCosts,
) -> None:
    for truth in truths:
        _draw(session, site_id, truth, config)
        log.seconds["draw"] += drawing_seconds(truth, config, costs) + costs.verdict_s
        log.counts["drawn"] += 1


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
    log = SessionLog(road_km=road_length_km(truths))
    used: set[int] = set()
    for _ in range(max_items):
        lease = session.call("POST", f"/api/sites/{site_id}/queue/next")
        if lease is None:
            break
        element = lease["element"]
        pending = _pending(session, site_id, element)
        decision = decide(
            _as_polyline(element), truths, used, config, [_as_polyline(e) for e in pending], costs
        )
        if decision.target is not None:
            used.add(decision.target)
        _apply(session, site_id, element, decision, pending)
        log.seconds[decision.kind] += decision.seconds(costs)
        log.counts[decision.kind] += 1
        log.counts["vertices_moved"] += decision.moved
        log.counts["pieces_merged"] += len(decision.merged)
        log.counts["gaps_drawn"] += decision.gaps
    else:
        raise SimulationError(f"site {site_id}: queue not empty after {max_items} items")
    _book_drawing(log, session, site_id, [t for i, t in enumerate(truths) if i not in used], config, costs)
    log.seconds["scan"] += log.road_km * 10 * costs.scan_per_100m_s
    return log


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
    log = SessionLog(road_km=road_length_km(truths))
    _book_drawing(log, session, site_id, truths, config, costs)
    log.seconds["scan"] += log.road_km * 10 * costs.scan_per_100m_s
    return log
