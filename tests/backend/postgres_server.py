"""A throwaway PostgreSQL server for the backend tests: a cluster in a temporary folder, Unix socket only.

Started once per test session when the PostgreSQL server programs are installed (`make test` installs them);
each test gets its own empty database on it. As root, the server runs as the `postgres` system user, since
PostgreSQL refuses to run as root.
"""

import glob
import itertools
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import sqlalchemy

SOCKET_PORT = 5432
"""Only names the socket file (`.s.PGSQL.5432`); nothing listens on TCP."""


def find_bin_dir() -> Path | None:
    """The folder of `initdb` and `pg_ctl`: on PATH, or Debian's versioned folder; None when not installed."""
    on_path = shutil.which("initdb")
    if on_path:
        return Path(on_path).resolve().parent
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(found[-1]).parent if found else None


class PostgresServer:
    """One cluster in a temporary folder; `database_url()` makes a fresh database per call."""

    def __init__(self, bin_dir: Path) -> None:
        self.bin_dir = bin_dir
        self.root = Path(tempfile.mkdtemp(prefix="cama-pg-"))
        self.data_dir = self.root / "data"
        self._names = itertools.count(1)
        self._as_postgres = os.geteuid() == 0
        if self._as_postgres:
            shutil.chown(self.root, user="postgres", group="postgres")

    def _run(self, *args: str) -> None:
        command = [str(self.bin_dir / args[0]), *args[1:]]
        if self._as_postgres:
            command = ["runuser", "-u", "postgres", "--", *command]
        result = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
        if result.returncode != 0:
            raise RuntimeError(
                f"{' '.join(command)} failed: {result.stderr.strip() or result.stdout.strip()}"
            )

    def start(self) -> None:
        """initdb (trust auth, user `cama`) and start on a socket in the temporary folder."""
        self._run("initdb", "-D", str(self.data_dir), "-U", "cama", "-A", "trust", "--no-sync", "-E", "UTF8")
        options = (
            f"-k {self.root} -c listen_addresses='' -p {SOCKET_PORT} -c fsync=off -c max_connections=200"
        )
        self._run(
            "pg_ctl", "-D", str(self.data_dir), "-o", options, "-w", "-l", str(self.root / "log"), "start"
        )

    def stop(self) -> None:
        """Stop the server and remove its folder."""
        try:
            self._run("pg_ctl", "-D", str(self.data_dir), "-m", "immediate", "-w", "stop")
        finally:
            shutil.rmtree(self.root, ignore_errors=True)

    def _url(self, database: str) -> str:
        return f"postgresql+psycopg://cama@/{database}?host={self.root}&port={SOCKET_PORT}"

    def database_url(self) -> str:
        """A new, empty database on the server."""
        name = f"cama_test_{next(self._names)}"
        engine = sqlalchemy.create_engine(self._url("postgres"), isolation_level="AUTOCOMMIT")
        try:
            with engine.connect() as connection:
                connection.execute(sqlalchemy.text(f'CREATE DATABASE "{name}"'))
        finally:
            engine.dispose()
        return self._url(name)
