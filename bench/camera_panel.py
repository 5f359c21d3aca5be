"""Camera panel benchmark (issue 25): time from selecting an element to its first image and to four images.

A real `cama serve` on loopback (pinned to two cores) holds a reconstructed site: registered on the surface
rasters of a `cama run` workspace with its data set, its proposals loaded as elements. With the server warm
(the site's camera context loaded by a first `/cameras` call), for a sample of elements the panel's requests
are made as the browser makes them:

- sequential: `GET /views?element_id=E&n=4`, then the four images one after the other (`?width=480`): first
  image = views + the first image; four images = views + all four;
- concurrent: `GET /views`, then the four images at once on four connections (`?width=320`, so that none is in
  the server's image cache from the sequential pass): first image = views + the first image to arrive, four
  images = views + the last one.

Each element is opened once per pass (no browser cache), so every image is encoded by the server unless an
earlier element's views shared it. Figures: median, p95 and max in milliseconds.

Usage (also through bench/editor.py --section camera-panel):
    .venv/bin/python bench/camera_panel.py --site data/synthetic/default [--workspace W] [--elements 40]
"""

import argparse
import json
import logging
import os
import random
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from annotations.schema import AnnotationSet  # noqa: E402
from app.backend.crud.site_sources import posed_sites  # noqa: E402
from app.demo import site_request  # noqa: E402
from cama_pipeline.workspace import Workspace  # noqa: E402
from tests.backend_system.system_helpers import ADMIN, PASSWORD, ServerProcess  # noqa: E402

logger = logging.getLogger(__name__)
RESULTS = Path(__file__).parent / "results"
SERVER_CPUS = (0, 1)
"""The issue's budget: two cores."""
SEQUENTIAL_WIDTH = 480
CONCURRENT_WIDTH = 320
"""Two widths, so that no image of the concurrent pass is in the server's cache from the sequential one (both
below the synthetic sites' 512 px, so that every image is scaled)."""


def quantiles(values: list[float]) -> dict[str, float] | None:
    """Median, 95th percentile and maximum (ms, 0.1 ms); None without values."""
    if not values:
        return None
    ordered = sorted(values)
    p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
    return {
        "median": round(ordered[len(ordered) // 2], 1),
        "p95": round(p95, 1),
        "max": round(ordered[-1], 1),
    }


def _login(client: httpx.Client, username: str) -> dict[str, str]:
    response = client.post("/api/auth/login", json={"username": username, "password": PASSWORD})
    response.raise_for_status()
    return {"Authorization": f"Bearer {response.json()['access_token']}"}


def seed(
    client: httpx.Client, dataset_root: Path, workspace: Workspace, recon_site: str
) -> tuple[int, dict[str, str]]:
    """Users, the reconstructed site and its proposals; the site id and an annotator's headers."""
    admin = _login(client, ADMIN)
    for username, role in (("lead", "lead"), ("ann", "annotator")):
        body = {"username": username, "password": PASSWORD, "role": role}
        client.post("/api/users", json=body, headers=admin).raise_for_status()
    lead = _login(client, "lead")
    bev, proposals = workspace.surface_bev(recon_site), workspace.proposals(recon_site)
    body = site_request(bev, bev, proposals, "bench").model_dump(mode="json", exclude_none=True)
    response = client.post("/api/sites", json={**body, "dataset_root": str(dataset_root)}, headers=lead)
    response.raise_for_status()
    site_id = int(response.json()["id"])
    elements = [
        {"class": e.cls, "points": [list(p) for p in e.points_2d], "confidence": e.confidence or 0.5}
        for e in AnnotationSet.read_json(proposals).elements
    ]
    bulk = {"elements": [{**e, "source": "proposal"} for e in elements]}
    client.post(
        f"/api/sites/{site_id}/elements/bulk", json=bulk, headers=lead, timeout=120.0
    ).raise_for_status()
    return site_id, _login(client, "ann")


def _views(client: httpx.Client, site_id: int, element_id: int, headers: dict[str, str]) -> list[str]:
    response = client.get(
        f"/api/sites/{site_id}/views", params={"element_id": element_id, "n": 4}, headers=headers
    )
    response.raise_for_status()
    return [view["token"] for view in response.json()["views"]]


def _image(client: httpx.Client, url: str, headers: dict[str, str]) -> float:
    """Fetch one image; the time it arrived (perf_counter)."""
    client.get(url, headers=headers).raise_for_status()
    return time.perf_counter()


def open_sequential(
    client: httpx.Client, site_id: int, element_id: int, headers: dict[str, str]
) -> list[float]:
    """Views, then each image in turn; ms from the start to each image (empty when no view sees it)."""
    start = time.perf_counter()
    tokens = _views(client, site_id, element_id, headers)
    urls = [f"/api/sites/{site_id}/images/{t}?width={SEQUENTIAL_WIDTH}" for t in tokens]
    return [(_image(client, url, headers) - start) * 1000 for url in urls]


def open_concurrent(
    clients: list[httpx.Client],
    pool: ThreadPoolExecutor,
    site_id: int,
    element_id: int,
    headers: dict[str, str],
) -> list[float]:
    """Views, then the images at once on separate connections; ms from the start to each image, sorted."""
    start = time.perf_counter()
    tokens = _views(clients[0], site_id, element_id, headers)
    urls = [f"/api/sites/{site_id}/images/{t}?width={CONCURRENT_WIDTH}" for t in tokens]
    done = list(pool.map(lambda pair: _image(pair[0], pair[1], headers), zip(clients, urls, strict=False)))
    return sorted((at - start) * 1000 for at in done)


def measure(base_url: str, site_id: int, headers: dict[str, str], n_elements: int) -> dict[str, Any]:
    """Warm the server, open a sample of elements in both ways; the figures."""
    clients = [httpx.Client(base_url=base_url, timeout=60.0) for _ in range(4)]
    try:
        client = clients[0]
        warm_start = time.perf_counter()
        status = client.get(f"/api/sites/{site_id}/cameras", headers=headers).json()
        warm_ms = (time.perf_counter() - warm_start) * 1000
        listed = client.get(
            f"/api/sites/{site_id}/elements", params={"limit": 100000}, headers=headers
        ).json()
        sample = random.Random(0).sample(listed, min(n_elements, len(listed)))
        _views(client, site_id, sample[0]["id"], headers)  # the first views call of the process (imports)
        sequential = [open_sequential(client, site_id, e["id"], headers) for e in sample]
        with ThreadPoolExecutor(max_workers=4) as pool:
            concurrent = [open_concurrent(clients, pool, site_id, e["id"], headers) for e in sample]
    finally:
        for each in clients:
            each.close()
    seen = [times for times in sequential if times]
    seen_concurrent = [times for times in concurrent if times]
    return {
        "camera_status": status,
        "context_load_ms": round(warm_ms, 1),
        "elements_sampled": len(sample),
        "elements_seen": len(seen),
        "elements_with_four_views": sum(len(times) == 4 for times in seen),
        "sequential": {
            "width": SEQUENTIAL_WIDTH,
            "first_image_ms": quantiles([times[0] for times in seen]),
            "four_images_ms": quantiles([times[-1] for times in seen if len(times) == 4]),
        },
        "concurrent": {
            "width": CONCURRENT_WIDTH,
            "first_image_ms": quantiles([times[0] for times in seen_concurrent]),
            "four_images_ms": quantiles([times[-1] for times in seen_concurrent if len(times) == 4]),
        },
    }


def run(site_dir: Path, workspace_dir: Path | None = None, n_elements: int = 40) -> dict[str, Any]:
    """Serve the reconstructed site on two cores and measure the camera panel's requests."""
    dataset_root = (site_dir / "nuscenes").resolve()
    workspace = Workspace.resolve(workspace_dir, dataset_root)
    sites = posed_sites(workspace.root)
    if not sites:
        raise SystemExit(f"{workspace.root}: no reconstruction with SfM poses; run `cama run` first")
    load_before = round(os.getloadavg()[0], 2)
    with tempfile.TemporaryDirectory() as tmp:
        roots = os.pathsep.join(str(p) for p in (Path(tmp), dataset_root, workspace.root.resolve()))
        server = ServerProcess(
            data_dir=Path(tmp) / "server", cpus=SERVER_CPUS, extra_env={"CAMA_DATA_ROOTS": roots}
        )
        server.start()
        try:
            with httpx.Client(base_url=server.base_url, timeout=60.0) as client:
                site_id, headers = seed(client, dataset_root, workspace, sites[0])
            figures = measure(server.base_url, site_id, headers, n_elements)
        finally:
            server.stop()
    return {
        "site": str(site_dir),
        "reconstruction": sites[0],
        "server_cpus": list(SERVER_CPUS),
        "load_average_1m_before": load_before,
        "load_average_1m_after": round(os.getloadavg()[0], 2),
        **figures,
    }


def write(figures: dict[str, Any], path: Path = RESULTS / "editor.json") -> None:
    """Put the figures under `camera_panel` in the editor bench's results, keeping every other key."""
    existing = json.loads(path.read_text()) if path.is_file() else {}
    path.parent.mkdir(exist_ok=True)
    path.write_text(json.dumps({**existing, "camera_panel": figures}, indent=2) + "\n")


def main() -> None:
    """Parse options, run, write bench/results/editor.json's `camera_panel`."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--workspace", type=Path, default=None, help="default: the site's workspace")
    parser.add_argument("--elements", type=int, default=40)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("httpx").setLevel(logging.WARNING)
    figures = run(args.site, args.workspace, args.elements)
    write(figures)
    logger.info("%s", json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
