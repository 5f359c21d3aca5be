"""The FastAPI application factory: `create_app(settings)` migrates the database and mounts the API."""

import logging
import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio.to_thread
from fastapi import FastAPI

from app.backend import crud
from app.backend.api.main import api_router
from app.backend.api.routes import frontend
from app.backend.auth_cache import TokenCache
from app.backend.config import Settings
from app.backend.db import make_engine, make_sessionmaker, upgrade
from app.backend.errors import install_error_handlers
from app.backend.jobs.export import EXPORT_JOB_KINDS
from app.backend.jobs.kinds import JOB_KINDS
from app.backend.jobs.runner import JobRunner
from app.backend.jobs.vma import unavailable_kinds, vma_job_kinds
from app.backend.login_limit import LoginLimiter
from app.backend.middleware import BodySizeLimit, ResponseHeaders
from app.backend.security import dummy_hash

logger = logging.getLogger(__name__)


WORKER_THREADS = int(os.environ.get("CAMA_WORKER_THREADS", "8"))
"""Worker threads for the synchronous endpoints (CAMA_WORKER_THREADS; anyio's default is 40). More threads than
the database pool has connections only queue inside the pool, and dozens of threads contending for the GIL
slow every request."""


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Size the endpoint thread pool; stop background jobs when the server shuts down (running ones end at
    their next step)."""
    if WORKER_THREADS < 1:
        raise ValueError(f"CAMA_WORKER_THREADS: must be >= 1, got {WORKER_THREADS}")
    anyio.to_thread.current_default_thread_limiter().total_tokens = WORKER_THREADS
    try:
        yield
    finally:
        app.state.jobs.shutdown()


def create_app(settings: Settings) -> FastAPI:
    """Migrate the database to the latest schema, bootstrap the first admin if asked, and build the app."""
    database_url = settings.resolved_database_url
    upgrade(database_url)
    engine = make_engine(database_url)
    sessions = make_sessionmaker(engine)
    if settings.admin_username:
        with sessions() as session:
            crud.ensure_admin(
                session=session,
                username=settings.admin_username,
                password=settings.admin_password,
                scrypt_n=settings.scrypt_n,
            )
    app = FastAPI(
        title="CAMA Studio",
        summary="HD-map annotation: sites, versioned vector elements, review and edit history.",
        docs_url=None,  # served by the frontend router with local Swagger UI files (the product runs offline)
        redoc_url=None,
        openapi_url="/openapi.json",
        lifespan=_lifespan,
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.sessionmaker = sessions
    app.state.token_cache = TokenCache()
    app.state.login_limiter = LoginLimiter.from_settings(settings)
    dummy_hash(settings.scrypt_n)  # made now, so that the first unknown user's login is not slower either
    app.state.jobs = JobRunner(
        sessions=sessions,
        data_dir=settings.data_dir,
        kinds={**JOB_KINDS, **EXPORT_JOB_KINDS, **vma_job_kinds(settings)},
        unavailable=unavailable_kinds(settings),
    )
    app.state.jobs.recover_interrupted()
    install_error_handlers(app)
    app.include_router(api_router)
    app.include_router(frontend.router)
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_payload_bytes)
    app.add_middleware(ResponseHeaders)  # added last, so outermost: the 413s get the headers too
    logger.info("backend ready on %s", engine.url.render_as_string(hide_password=True))
    return app
