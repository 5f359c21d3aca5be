"""Load benchmark of the annotation API: edit round-trips by many concurrent clients against a real server.

Each client repeats: GET an element, PATCH it with the version read; on 409 it retries with the version in the
conflict body. The latency of one edit round-trip runs from the GET to the acknowledged PATCH (retries included).
The server is `cama serve` (uvicorn, one process) on loopback with SQLite in a temporary folder, and also with
PostgreSQL: at a given URL (`--postgres-url` or CAMA_BENCH_POSTGRES_URL; that database must be empty or already
migrated by CAMA, and is written to), else on a throwaway cluster when the PostgreSQL server programs are
installed (the backend tests' `PostgresServer`: Unix socket, fsync off, a fresh database per server run).

The load generator is lean so that it takes little of the CPU the server is measured on: one asyncio loop, one
keep-alive HTTP/1.1 connection per client written and parsed by hand (no HTTP library per request). With
`--client-cpus` / `--server-cpus` the two are pinned to separate cores (Linux affinity); on a shared machine
other processes still run on both, so the load average is recorded before and after every run.

Two runs per server: `paced` (each client pauses a random time of mean --think-ms between edits, as an
annotator does; latency under realistic load) and `saturation` (no pause: the server's capacity, where latency
is queueing by Little's law, clients / throughput).

With `--baseline-ref REF` the same runs are also made, in the same conditions and interleaved, against a server
started from the sources of git commit REF (`git archive`): a before/after comparison.

The `lint` case (issue 21, point 3) loads the probe's site, 60 dividers x 5,000 vertices (wavy, 1.6 m apart:
every neighbour pair is narrow), in one bulk request to a SQLite server, then times `GET /lint`: the first build,
warm answers, and the lint after each of `--lint-edits` edits of one divider. The server runs with
CAMA_LINT_BUDGET_S=600 so that the first build is measured whole.

Usage: .venv/bin/python bench/api_load.py [--cases load lint] [--clients 50] [--duration-s 15] [--think-ms 1000]
       [--server-cpus 1] [--client-cpus 0] [--baseline-ref HEAD~1] [--postgres-url URL] [--lint-edits 5]
Prints the figures and writes them to bench/results/api_load.json (with the command line); running some of the
cases replaces their figures there and keeps the others'.
"""

import argparse
import asyncio
import json
import os
import platform
import random
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the test helpers, `tests` a package at the repository root
from tests.backend.postgres_server import PostgresServer, find_bin_dir  # noqa: E402
from tests.backend_system.system_helpers import (  # noqa: E402
    ServerProcess,
    create_elements,
    divider_points,
    login,
    register_site,
)

RESULTS = Path(__file__).parent / "results"
MAX_RETRIES = 20
IDLE_RECONNECT_S = 4.0
"""A client idle this long opens a new connection (uvicorn closes keep-alive connections idle for 5 s)."""
SOURCE_PACKAGES = ("app", "cama_pipeline", "annotations", "models", "cama_studio")
"""What a baseline server needs from its commit, those of them the commit has (the rest of the environment is
shared)."""


@dataclass
class ClientStats:
    """One client's measurements."""

    latencies_s: list[float] = field(default_factory=list)
    conflicts: int = 0
    errors: list[str] = field(default_factory=list)


class HttpConnection:
    """A minimal keep-alive HTTP/1.1 client for JSON requests (enough for this server's responses)."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, auth: str) -> None:
        self.reader, self.writer = reader, writer
        self.prefix = f"Host: bench\r\nAuthorization: {auth}\r\n"

    @classmethod
    async def open(cls, port: int, auth: str) -> "HttpConnection":
        """Connect to the server on loopback."""
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        return cls(reader, writer, auth)

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, Any]:
        """Send one request and return the status and the decoded JSON body."""
        head = f"{method} {path} HTTP/1.1\r\n{self.prefix}"
        if body is None:
            self.writer.write(f"{head}\r\n".encode())
        else:
            payload = json.dumps(body).encode()
            head += f"Content-Type: application/json\r\nContent-Length: {len(payload)}\r\n\r\n"
            self.writer.write(head.encode() + payload)
        header = await self.reader.readuntil(b"\r\n\r\n")
        lines = header.decode("latin-1").split("\r\n")
        length = next(
            (int(line.split(":", 1)[1]) for line in lines if line.lower().startswith("content-length:")), 0
        )
        content = await self.reader.readexactly(length)
        return int(lines[0].split(" ", 2)[1]), json.loads(content) if content else None

    async def close(self) -> None:
        """Close the connection."""
        self.writer.close()
        await self.writer.wait_closed()


async def edit(connection: HttpConnection, url: str, points: list[list[float]], stats: ClientStats) -> None:
    """One edit round-trip: GET, then PATCH with the version read, retrying with the version of each 409."""
    status, element = await connection.request("GET", url)
    if status != 200:
        raise RuntimeError(f"GET {url}: {status} {element}")
    version = element["version"]
    for _ in range(MAX_RETRIES):
        status, body = await connection.request("PATCH", url, {"version": version, "points": points})
        if status == 200:
            return
        if status != 409:
            raise RuntimeError(f"PATCH {url}: {status} {body}")
        stats.conflicts += 1
        version = body["current"]["version"]
    raise RuntimeError(f"PATCH {url}: still conflicting after {MAX_RETRIES} retries")


async def client_loop(
    port: int, auth: str, urls: list[str], seed: int, deadline: float, think_s: float, stats: ClientStats
) -> None:
    """Edit random elements until `deadline`; between edits think an exponentially distributed time of mean
    `think_s` (0 = back to back, a saturation test). The first pause is random too, so clients start spread."""
    rng = random.Random(seed)
    connection = await HttpConnection.open(port, auth)
    last_request = time.perf_counter()
    try:
        if think_s > 0:
            await asyncio.sleep(rng.uniform(0.0, think_s))
        while time.perf_counter() < deadline:
            if time.perf_counter() - last_request > IDLE_RECONNECT_S:  # the server drops idle connections
                await connection.close()
                connection = await HttpConnection.open(port, auth)
            url = rng.choice(urls)
            points = divider_points(rng.uniform(1.0, 80.0), rng.uniform(1.0, 80.0))
            started = time.perf_counter()
            try:
                await edit(connection, url, points, stats)
            except (OSError, asyncio.IncompleteReadError, RuntimeError, KeyError, ValueError) as error:
                stats.errors.append(repr(error))
                await connection.close()
                connection = await HttpConnection.open(port, auth)
                continue
            last_request = time.perf_counter()
            stats.latencies_s.append(last_request - started)
            if think_s > 0:
                await asyncio.sleep(min(rng.expovariate(1.0 / think_s), max(0.0, deadline - last_request)))
    finally:
        await connection.close()


def percentile_ms(values_s: list[float], q: float) -> float:
    """The q-th percentile (0..100) in milliseconds."""
    return 1000.0 * statistics.quantiles(values_s, n=1000, method="inclusive")[round(q * 10) - 1]


def seed_site(server: ServerProcess, n_elements: int) -> tuple[str, list[str]]:
    """Log in, register a site and create its elements; the Authorization value and the element URLs."""
    with httpx.Client(base_url=server.base_url, timeout=30.0) as client:
        headers = login(client)
        site_id = register_site(client, headers, server.data_dir / "bev", name=f"load-{time.time_ns()}")
        ids = create_elements(client, headers, site_id, n_elements)
    return headers["Authorization"], [f"/api/sites/{site_id}/elements/{i}" for i in ids]


def run_load(
    server: ServerProcess, *, clients: int, duration_s: float, n_elements: int, think_s: float
) -> dict[str, Any]:
    """Seed a site and elements, run the clients for `duration_s`, return the figures."""
    auth, urls = seed_site(server, n_elements)
    stats = [ClientStats() for _ in range(clients)]
    load_before = os.getloadavg()[0]
    cpu_before = server_cpu_s(server)
    started = time.perf_counter()

    async def all_clients() -> None:
        deadline = time.perf_counter() + duration_s
        await asyncio.gather(
            *(client_loop(server.port, auth, urls, n, deadline, think_s, stats[n]) for n in range(clients))
        )

    asyncio.run(all_clients())
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
        "server_cpu_ms_per_edit": round(1000.0 * (server_cpu_s(server) - cpu_before) / len(latencies), 2),
        "conflicts_retried": sum(s.conflicts for s in stats),
        "errors": len(errors),
        "first_errors": errors[:5],
        "load_average_1min_before_after": [round(load_before, 2), round(os.getloadavg()[0], 2)],
    }


def server_cpu_s(server: ServerProcess) -> float:
    """CPU seconds (user + system) the server process has used so far (Linux /proc)."""
    assert server.process is not None
    fields = Path(f"/proc/{server.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def export_tree(ref: str, folder: Path) -> Path:
    """The source packages of git commit `ref`, unpacked under `folder`."""
    listed = subprocess.run(
        ["git", "-C", str(ROOT), "ls-tree", "--name-only", ref], check=True, capture_output=True, text=True
    ).stdout.split()
    archive = subprocess.run(
        [
            "git",
            "-C",
            str(ROOT),
            "archive",
            "--format=tar",
            ref,
            *[p for p in SOURCE_PACKAGES if p in listed],
        ],
        check=True,
        capture_output=True,
    ).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(folder, filter="data")
    return folder


def bench_server(
    label: str,
    database: Callable[[], str | None],
    args: argparse.Namespace,
    source: Path | None,
    think_ms: float,
) -> dict[str, Any]:
    """Start a server (from `source` when given, else this checkout) on `database()`, run one mode, stop it."""
    env = {"PYTHONPATH": str(source)} if source is not None else {}
    with tempfile.TemporaryDirectory(prefix=f"cama-load-{label}-") as folder:
        server = ServerProcess(
            data_dir=Path(folder), database_url=database(), cpus=args.server_cpus, extra_env=env
        ).start()
        try:
            return run_load(
                server,
                clients=args.clients,
                duration_s=args.duration_s,
                n_elements=args.elements,
                think_s=think_ms / 1000.0,
            )
        finally:
            server.stop()


def bench_database(
    label: str, database: Callable[[], str | None], args: argparse.Namespace, baseline: Path | None
) -> dict[str, Any]:
    """Paced and saturation runs on one database; with a baseline tree, each run is made on both servers
    back to back (baseline first), so that the two see the same machine load."""
    results: dict[str, Any] = {}
    for mode, think_ms in (("paced", args.think_ms), ("saturation", 0.0)):
        if baseline is not None:
            results.setdefault("baseline", {})[mode] = bench_server(label, database, args, baseline, think_ms)
        results[mode] = bench_server(label, database, args, None, think_ms)
        print(f"{label} {mode}: {json.dumps(results)}", file=sys.stderr)
    return results


def bench_postgres(args: argparse.Namespace, baseline: Path | None) -> dict[str, Any]:
    """The runs on PostgreSQL: at the given URL, else on a throwaway cluster, else skipped with the reason."""
    if args.postgres_url:
        return {
            "database": "given URL",
            **bench_database("postgresql", lambda: args.postgres_url, args, baseline),
        }
    if args.no_postgres:
        return {"skipped": "--no-postgres"}
    bin_dir = find_bin_dir()
    if bin_dir is None:
        return {"skipped": "no --postgres-url given and no PostgreSQL server programs installed"}
    cluster = PostgresServer(bin_dir)
    cluster.start()
    try:
        figures = bench_database("postgresql", cluster.database_url, args, baseline)
    finally:
        cluster.stop()
    return {"database": "throwaway cluster: Unix socket, fsync off, fresh database per server run", **figures}


LINT_SITE = (60, 5000)
"""The probe's site of issue 21: dividers x vertices per divider."""


def probe_site_bodies(dividers: int, vertices: int) -> list[dict[str, Any]]:
    """Wavy dividers 1.6 m apart across the 100 m site (as `tests/backend/test_lint_bounded.py` builds it)."""
    x = np.linspace(0.0, 99.0, vertices)
    return [
        {"class": "divider", "points": np.c_[x, 2.0 + 1.6 * k + 0.2 * np.sin(x / 3.0)].round(4).tolist()}
        for k in range(dividers)
    ]


def timed_get(client: httpx.Client, url: str, headers: dict[str, str]) -> tuple[float, Any]:
    """Seconds a GET took, and its JSON; RuntimeError unless 200."""
    started = time.perf_counter()
    response = client.get(url, headers=headers)
    elapsed_s = time.perf_counter() - started
    if response.status_code != 200:
        raise RuntimeError(f"GET {url}: {response.status_code} {response.text[:300]}")
    return elapsed_s, response.json()


def run_lint(server: ServerProcess, edits: int) -> dict[str, Any]:
    """Load the probe's site, then time its lint: first build, warm, after each edit of one divider."""
    load_before = os.getloadavg()[0]
    with httpx.Client(base_url=server.base_url, timeout=1800.0) as client:
        headers = login(client)
        site_id = register_site(client, headers, server.data_dir / "bev", name=f"lint-{time.time_ns()}")
        url = f"/api/sites/{site_id}"
        started = time.perf_counter()
        response = client.post(
            f"{url}/elements/bulk", json={"elements": probe_site_bodies(*LINT_SITE)}, headers=headers
        )
        create_s = time.perf_counter() - started
        if response.status_code != 201:
            raise RuntimeError(f"bulk create: {response.status_code} {response.text[:300]}")
        elements = response.json()
        cpu_before = server_cpu_s(server)
        first_s, first = timed_get(client, f"{url}/lint", headers)
        first_cpu_s = server_cpu_s(server) - cpu_before
        warm_s = [timed_get(client, f"{url}/lint", headers)[0] for _ in range(5)]
        edit_s = []
        for k in range(edits):
            index = (29 + 7 * k) % len(elements)
            element, dy = elements[index], 0.3 if k % 2 == 0 else -0.3
            body = {"version": element["version"], "points": [[x, y + dy] for x, y in element["points"]]}
            patched = client.patch(f"{url}/elements/{element['id']}", json=body, headers=headers)
            if patched.status_code != 200:
                raise RuntimeError(f"PATCH: {patched.status_code} {patched.text[:300]}")
            elements[index] = patched.json()
            edit_s.append(timed_get(client, f"{url}/lint", headers)[0])
    return {
        "create_s": round(create_s, 2),
        "first_lint_s": round(first_s, 2),
        "first_lint_server_cpu_s": round(first_cpu_s, 2),
        "warm_lint_ms": round(1000.0 * statistics.median(warm_s), 1),
        "edit_lint_ms": round(1000.0 * statistics.median(edit_s), 1) if edit_s else None,
        "edit_lint_max_ms": round(1000.0 * max(edit_s), 1) if edit_s else None,
        "findings": len(first["findings"]),
        "pending_elements": first.get("pending_elements"),
        "load_average_1min_before_after": [round(load_before, 2), round(os.getloadavg()[0], 2)],
    }


def bench_lint(args: argparse.Namespace, source: Path | None) -> dict[str, Any]:
    """The lint case on a SQLite server from `source` (else this checkout)."""
    env = {"CAMA_LINT_BUDGET_S": "600", "CAMA_MAX_PAYLOAD_BYTES": str(32 * 1024 * 1024)}
    if source is not None:
        env["PYTHONPATH"] = str(source)
    with tempfile.TemporaryDirectory(prefix="cama-lint-") as folder:
        server = ServerProcess(data_dir=Path(folder), cpus=args.server_cpus, extra_env=env).start()
        try:
            figures = run_lint(server, args.lint_edits)
        finally:
            server.stop()
    print(f"lint {'baseline' if source else 'current'}: {json.dumps(figures)}", file=sys.stderr)
    return figures


def lint_case(args: argparse.Namespace, baseline: Path | None) -> dict[str, Any]:
    """The lint case's record: its command and conditions, the current server's figures and the baseline's."""
    dividers, vertices = LINT_SITE
    record: dict[str, Any] = {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "config": {
            "dividers": dividers,
            "vertices_per_divider": vertices,
            "edits": args.lint_edits,
            "server_cpus": list(args.server_cpus) if args.server_cpus else "all",
            "baseline_ref": args.baseline_ref or None,
        },
        "machine": machine(),
    }
    if baseline is not None:
        record["baseline"] = bench_lint(args, baseline)
    record["current"] = bench_lint(args, None)
    return record


def machine() -> dict[str, Any]:
    """The machine the figures come from."""
    return {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()}


def parse_cpus(text: str) -> tuple[int, ...] | None:
    """`0,1` -> (0, 1); empty -> None (all cores)."""
    return tuple(int(part) for part in text.split(",")) if text else None


CASES = ("load", "lint")
"""`load`: concurrent edit round-trips (the top-level figures); `lint`: the probe's site (under "lint")."""


def parse_args() -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=50)
    parser.add_argument("--duration-s", type=float, default=15.0)
    parser.add_argument("--elements", type=int, default=200, help="Elements the clients pick from at random.")
    parser.add_argument("--server-cpus", type=parse_cpus, default=None, help="Pin the server, e.g. 1.")
    parser.add_argument(
        "--client-cpus", type=parse_cpus, default=None, help="Pin the load generator, e.g. 0."
    )
    parser.add_argument("--postgres-url", default=os.environ.get("CAMA_BENCH_POSTGRES_URL", ""))
    parser.add_argument("--no-postgres", action="store_true", help="Skip PostgreSQL (no throwaway cluster).")
    parser.add_argument("--baseline-ref", default="", help="Also measure a server from this git commit.")
    parser.add_argument(
        "--think-ms",
        type=float,
        default=1000.0,
        help="Mean pause between a client's edits in the paced run (an annotator's edit rhythm); "
        "a saturation run with no pause follows.",
    )
    parser.add_argument(
        "--cases", nargs="+", choices=CASES, default=list(CASES), help="Which cases to run (default: all)."
    )
    parser.add_argument("--lint-edits", type=int, default=5, help="Edits timed in the lint case.")
    parser.add_argument("--output", type=Path, default=RESULTS / "api_load.json")
    args = parser.parse_args()
    if args.clients < 1 or args.duration_s <= 0 or args.elements < 1:
        parser.error("--clients, --duration-s and --elements must be positive")
    return args


def load_case(args: argparse.Namespace, baseline: Path | None) -> dict[str, Any]:
    """The load case's figures, with its command and conditions."""
    return {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "config": {
            "clients": args.clients,
            "duration_s": args.duration_s,
            "elements": args.elements,
            "paced_mean_think_ms": args.think_ms,
            "server_cpus": list(args.server_cpus) if args.server_cpus else "all",
            "client_cpus": list(args.client_cpus) if args.client_cpus else "all",
            "baseline_ref": args.baseline_ref or None,
        },
        "machine": machine(),
        "sqlite": bench_database("sqlite", lambda: None, args, baseline),
        "postgresql": bench_postgres(args, baseline),
    }


def main() -> None:
    args = parse_args()
    if args.client_cpus:
        os.sched_setaffinity(0, set(args.client_cpus))
    results: dict[str, Any] = {}
    if set(args.cases) != set(CASES) and args.output.exists():
        results = json.loads(args.output.read_text())  # keep the figures of the cases not run
    with tempfile.TemporaryDirectory(prefix="cama-load-baseline-") as folder:
        baseline = export_tree(args.baseline_ref, Path(folder)) if args.baseline_ref else None
        if "load" in args.cases:
            results.update(load_case(args, baseline))
        if "lint" in args.cases:
            results["lint"] = lint_case(args, baseline)
    print(json.dumps(results, indent=2))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
