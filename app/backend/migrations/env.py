"""Alembic environment: runs migrations online against the URL set by `app.backend.db.upgrade`."""

import logging

from alembic import context

from app.backend import (
    models_jobs,  # noqa: F401  (registers the jobs table)
    models_reprojection,  # noqa: F401  (registers the reprojection figures' cache)
    models_review,  # noqa: F401  (registers the queue and issue tables)
)
from app.backend.db import make_engine
from app.backend.models import Base

logger = logging.getLogger(__name__)
target_metadata = Base.metadata


def run_migrations_online() -> None:
    """Apply migrations in one transaction on an engine with the backend's connection settings."""
    url = context.config.get_main_option("sqlalchemy.url")
    if not url:
        raise ValueError("sqlalchemy.url: no database URL configured for migrations")
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
            with context.begin_transaction():
                context.run_migrations()
    finally:
        engine.dispose()


if context.is_offline_mode():
    raise RuntimeError("offline (SQL script) migrations are not supported; run app.backend.db.upgrade")
run_migrations_online()
