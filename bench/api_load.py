"""Load benchmark of the annotation API: edit round-trips by many concurrent clients against a real server.

Each client repeats: GET an element, PATCH it with the version read; on 409 it retries with the version in the
conflict body. The latency of one edit round-trip runs from the GET to the acknowledged PATCH (retries included).
The server is `cama serve` (uvicorn, one process) on loopback with SQLite in a temporary folder, and also with
PostgreSQL when a URL is given (`--postgres-url` or CAMA_BENCH_POSTGRES_URL; that database must be empty or
already migrated by CAMA, and is written to).

Two runs per database: `paced` (each client pauses a random time of mean --think-ms between edits, as an
annotator does; latency under realistic load) and `saturation` (no pause: the server's capacity, where latency
is queueing by Little's law, clients / throughput).

Usage: .venv/bin/python bench/api_load.py [--clients 50] [--duration-s 15] [--think-ms 1000] [--server-cpus 0,1]
Prints the figures and writes them to bench/results/api_load.json.
"""

import argparse
import json
import os
import platform
import random
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "backend_system"))
from system_helpers import ServerProcess, create_elements, divider_points, login, register_site  # noqa: E402

RESULTS = Path(__file__).parent / "results"
MAX_RETRIES = 20
MAX_EDITS_PER_CLIENT = 5000


@dataclass
class ClientStats:
    """One client's measurements."""

    latencies_s: list[float] = field(default_factory=list)
    conflicts: int = 0
    errors: list[str] = field(default_factory=list)


def client_loop(
    base_url: str,
    headers: dict[str, str],
    site_id: int,
    ids: list[int],
    seed: int,
    stop: threading.Event,
    stats: ClientStats,
    think_s: float = 0.0,
) -> None:
    """Edit random elements until `stop` is set or the per-client cap is reached; between edits a client
    thinks for an exponentially distributed time of mean `think_s` (0 = back to back, a saturation test)."""
    rng = random.Random(seed)
    with httpx.Client(base_url=base_url, headers=headers, timeout=30.0) as client:
        while not stop.is_set() and len(stats.latencies_s) < MAX_EDITS_PER_CLIENT:
            element_id = rng.choice(ids)
            url = f"/api/sites/{site_id}/elements/{element_id}"
            points = divider_points(rng.uniform(1.0, 80.0), rng.uniform(1.0, 80.0))
            started = time.perf_counter()
            try:
                version = client.get(url).raise_for_status().json()["version"]
                for _ in range(MAX_RETRIES):
                    response = client.patch(url, json={"version": version, "points": points})
                    if response.status_code != 409:
                        break
                    stats.conflicts += 1
                    version = response.json()["current"]["version"]
                response.raise_for_status()
            except (httpx.HTTPError, KeyError, TypeError) as error:
                stats.errors.append(repr(error))
                continue
            stats.latencies_s.append(time.perf_counter() - started)
            if think_s > 0:
                stop.wait(rng.expovariate(1.0 / think_s))


def percentile_ms(values_s: list[float], q: float) -> float:
    """The q-th percentile (0..100) in milliseconds."""
    return 1000.0 * statistics.quantiles(values_s, n=1000, method="inclusive")[round(q * 10) - 1]


def run_load(
    server: ServerProcess, *, clients: int, duration_s: float, n_elements: int, think_s: float
) -> dict[str, Any]:
    """Seed a site and elements, run the clients for `duration_s`, return the figures."""
    with httpx.Client(base_url=server.base_url, timeout=30.0) as client:
        headers = login(client)
        site_id = register_site(client, headers, server.data_dir / "bev", name=f"load-{time.time_ns()}")
        ids = create_elements(client, headers, site_id, n_elements)
    stop = threading.Event()
    stats = [ClientStats() for _ in range(clients)]
    workers = [
        threading.Thread(
            target=client_loop, args=(server.base_url, headers, site_id, ids, n, stop, stats[n], think_s)
        )
        for n in range(clients)
    ]
    started = time.perf_counter()
    for worker in workers:
        worker.start()
    time.sleep(duration_s)
    stop.set()
    for worker in workers:
        worker.join(timeout=60)
    elapsed_s = time.perf_counter() - started
    latencies = [value for s in stats for value in s.latencies_s]
    errors = [error for s in stats for error in s.errors]
    if len(latencies) < 2:
        raise RuntimeError(f"too few edits completed ({len(latencies)}); errors: {errors[:5]}")
    return {
        "mean_think_ms": round(1000 * think_s),
        "edits": len(latencies),
        "elapsed_s": round(elapsed_s, 2),
        "throughput_edits_per_s": round(len(latencies) / elapsed_s, 1),
        "p50_ms": round(percentile_ms(latencies, 50), 2),
        "p99_ms": round(percentile_ms(latencies, 99), 2),
        "max_ms": round(1000.0 * max(latencies), 2),
        "conflicts_retried": sum(s.conflicts for s in stats),
        "errors": len(errors),
        "first_errors": errors[:5],
    }


def bench_backend(label: str, database_url: str | None, args: argparse.Namespace) -> dict[str, Any]:
    """Start a server for one database, measure, stop it."""
    with tempfile.TemporaryDirectory(prefix=f"cama-load-{label}-") as folder:
        server = ServerProcess(
            data_dir=Path(folder), database_url=database_url, cpus=args.server_cpus
        ).start()
        try:
            return {
                mode: run_load(
                    server,
                    clients=args.clients,
                    duration_s=args.duration_s,
                    n_elements=args.elements,
                    think_s=think_ms / 1000.0,
                )
                for mode, think_ms in (("paced", args.think_ms), ("saturation", 0.0))
            }
        finally:
            server.stop()


def parse_cpus(text: str) -> tuple[int, ...] | None:
    """`0,1` -> (0, 1); empty -> None (all cores)."""
    return tuple(int(part) for part in text.split(",")) if text else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=50)
    parser.add_argument("--duration-s", type=float, default=15.0)
    parser.add_argument("--elements", type=int, default=200, help="Elements the clients pick from at random.")
    parser.add_argument("--server-cpus", type=parse_cpus, default=None, help="Pin the server, e.g. 0,1.")
    parser.add_argument("--postgres-url", default=os.environ.get("CAMA_BENCH_POSTGRES_URL", ""))
    parser.add_argument(
        "--think-ms",
        type=float,
        default=1000.0,
        help="Mean pause between a client's edits in the paced run (an annotator's edit rhythm); "
        "a saturation run with no pause follows.",
    )
    parser.add_argument("--output", type=Path, default=RESULTS / "api_load.json")
    args = parser.parse_args()
    if args.clients < 1 or args.duration_s <= 0 or args.elements < 1:
        parser.error("--clients, --duration-s and --elements must be positive")

    results: dict[str, Any] = {
        "config": {
            "clients": args.clients,
            "duration_s": args.duration_s,
            "elements": args.elements,
            "paced_mean_think_ms": args.think_ms,
            "server_cpus": list(args.server_cpus) if args.server_cpus else "all",
        },
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
        },
        "sqlite": bench_backend("sqlite", None, args),
    }
    if args.postgres_url:
        results["postgresql"] = bench_backend("postgresql", args.postgres_url, args)
    else:
        results["postgresql"] = {"skipped": "no --postgres-url / CAMA_BENCH_POSTGRES_URL given"}
    print(json.dumps(results, indent=2))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
