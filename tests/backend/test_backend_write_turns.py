"""SQLite write turns: a session holds the process's write lock from its first write until its transaction
ends (commit, rollback or close); readers never take it; concurrent writers all land."""

import threading
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from app.backend.db import SqliteWriteTurns, make_engine, make_sessionmaker, upgrade
from app.backend.models import Site


def site(name: str) -> Site:
    return Site(
        name=name,
        site_origin_x=0.0,
        site_origin_y=0.0,
        georeference={},
        raster_dir="/r",
        created_at=datetime.now(UTC),
    )


def turns_of(factory: sessionmaker[Session]) -> SqliteWriteTurns:
    turns = SqliteWriteTurns()
    turns.install(factory)
    return turns


def test_the_turn_is_held_from_the_first_write_until_the_transaction_ends(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'w.db'}"
    upgrade(url)
    engine = make_engine(url)
    factory = sessionmaker(bind=engine, expire_on_commit=False)
    turns = turns_of(factory)
    with factory() as session:
        session.query(Site).all()
        assert not turns.lock.locked()  # reading takes no turn
        session.add(site("a"))
        session.flush()
        assert turns.lock.locked()
        session.commit()
        assert not turns.lock.locked()
        session.execute(update(Site).values(raster_dir="/s"))
        assert turns.lock.locked()
        session.rollback()
        assert not turns.lock.locked()
        session.add(site("b"))
        session.flush()
    assert not turns.lock.locked()  # closed without commit
    engine.dispose()


def test_concurrent_writers_all_land(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'c.db'}"
    upgrade(url)
    engine = make_engine(url)
    factory = make_sessionmaker(engine)

    def write(worker: int) -> None:
        for n in range(10):
            with factory() as session:
                session.add(site(f"{worker}-{n}"))
                session.commit()

    threads = [threading.Thread(target=write, args=(k,)) for k in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    with factory() as session:
        assert session.query(Site).count() == 80
    engine.dispose()
