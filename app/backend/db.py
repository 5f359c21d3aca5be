"""Database engines and schema migrations: one engine per `Settings`, never at import time."""

import logging
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from alembic import command
from alembic.config import Config
from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import ORMExecuteState, Session, SessionTransaction, sessionmaker

logger = logging.getLogger(__name__)

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
SQLITE_BUSY_TIMEOUT_MS = 5000


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    """WAL journal (readers never block the writer), foreign keys on, and wait rather than fail when busy."""
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.close()


def make_engine(database_url: str) -> Engine:
    """An engine for the URL; SQLite gets its pragmas on every connection and its folder created."""
    url = make_url(database_url)
    if url.get_backend_name() != "sqlite":
        return create_engine(database_url, pool_pre_ping=True)
    if url.database and url.database != ":memory:":
        Path(url.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(database_url, connect_args={"check_same_thread": False})
    event.listen(engine, "connect", _sqlite_pragmas)
    return engine


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    """Sessions that keep loaded objects readable after commit (responses are built after it); on SQLite
    their write transactions take turns through `SqliteWriteTurns`."""
    factory = sessionmaker(bind=engine, expire_on_commit=False)
    if engine.dialect.name == "sqlite":
        SqliteWriteTurns().install(factory)
    return factory


class SqliteWriteTurns:
    """One writing session at a time per process, queued on a Python lock.

    SQLite lets one transaction write at a time; a second writer waits in SQLite's busy handler, which sleeps
    in steps of up to 100 ms and so wakes late: under many concurrent edits those sleeps add to the slow tail
    of the latency. Here a session takes the lock before its first write (a flush or an ORM DML statement) and
    hands it on when its transaction ends (commit, rollback or close), so a waiting writer wakes as soon as
    the previous one is done. Writers of other processes are still arbitrated by SQLite's busy timeout, and
    so is a writer that waited here longer than that timeout (a safety net, never expected).
    """

    KEY = "cama_write_turn"

    def __init__(self) -> None:
        self.lock = threading.Lock()

    def install(self, factory: sessionmaker[Session]) -> None:
        """Listen on the sessions `factory` makes."""
        event.listen(factory, "before_flush", self._before_flush)
        event.listen(factory, "do_orm_execute", self._on_execute)
        event.listen(factory, "after_transaction_end", self._after_transaction_end)

    def _take(self, session: Session) -> None:
        """Wait for the turn unless this session holds it already."""
        if self.KEY not in session.info:
            session.info[self.KEY] = self.lock.acquire(timeout=SQLITE_BUSY_TIMEOUT_MS / 1000.0)

    def _before_flush(self, session: Session, _context: Any, _instances: Any) -> None:
        self._take(session)

    def _on_execute(self, state: ORMExecuteState) -> None:
        if state.is_insert or state.is_update or state.is_delete:
            self._take(state.session)

    def _after_transaction_end(self, session: Session, transaction: SessionTransaction) -> None:
        if transaction.parent is None and session.info.pop(self.KEY, False):
            self.lock.release()


def session_scope(factory: sessionmaker[Session]) -> Iterator[Session]:
    """Yield one session per request and close it; crud functions commit their own transactions."""
    with factory() as session:
        yield session


def alembic_config(database_url: str) -> Config:
    """An Alembic configuration pointing at this package's migrations, without an ini file."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", database_url.replace("%", "%%"))
    return config


def upgrade(database_url: str, revision: str = "head") -> None:
    """Bring the database schema up to `revision` (the latest by default) with Alembic."""
    logger.info("migrating database to %s", revision)
    command.upgrade(alembic_config(database_url), revision)
