"""`cama serve`: run the backend with uvicorn."""

import gc
import logging
import os
from pathlib import Path
from typing import Annotated, Any

import typer

from app.backend.config import Settings
from app.backend.vma_loop import with_shipped_registry
from cama_pipeline.console import bad_input, failure

logger = logging.getLogger(__name__)

ACCESS_LOG = os.environ.get("CAMA_ACCESS_LOG", "") == "1"
"""uvicorn's per-request access log (CAMA_ACCESS_LOG=1); off by default: a log line per request cost about
3 % of the server's CPU under edit load, and every change is in the edit log anyway."""


def serve_command(
    data_dir: Annotated[Path, typer.Argument(help="Folder for the server's database and state.")],
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="TCP port.")] = 8000,
    database_url: Annotated[
        str | None, typer.Option(help="SQLAlchemy URL (e.g. postgresql://...); default SQLite in data_dir.")
    ] = None,
    admin_username: Annotated[
        str | None,
        typer.Option(help="Create this admin if there are no users; password from CAMA_ADMIN_PASSWORD."),
    ] = None,
    vma_registry: Annotated[
        Path | None,
        typer.Option(
            help="VMA checkpoint registry for retrain and proposal-refresh jobs (CAMA_VMA_REGISTRY); default "
            "DATA_DIR/vma-registry, seeded with the shipped model on first start."
        ),
    ] = None,
    vma_model: Annotated[
        str | None,
        typer.Option(
            help="auto, masks or maptr: which shipped network seeds the default registry (CAMA_VMA_MODEL); "
            "masks: DATA_DIR/vma-mask-registry, maptr: DATA_DIR/vma-registry; auto (default): masks unless "
            "DATA_DIR holds only a MapTR-style registry."
        ),
    ] = None,
    validation_site: Annotated[
        list[Path] | None,
        typer.Option(
            help="Held-out site folder for the retrain gate; repeat for several (CAMA_VMA_VALIDATION_SITES)."
        ),
    ] = None,
    validation_reconstructed: Annotated[
        list[Path] | None,
        typer.Option(
            help="Held-out synthetic site (`cama run` done) the retrain gate scores on its reconstructed "
            "rasters; repeat for several (CAMA_VMA_VALIDATION_RECONSTRUCTED)."
        ),
    ] = None,
    review_url: Annotated[
        str | None,
        typer.Option(help="The viser 3D review's URL (or :<port>) for the editor's link (CAMA_REVIEW_URL)."),
    ] = None,
) -> None:
    """Serve the annotation API (OpenAPI at /docs); settings from CAMA_* variables, options win."""
    from app.backend.main import create_app
    from app.backend.poll_log import quiet_change_polls

    try:
        settings = with_shipped_registry(
            Settings.from_env(
                data_dir=data_dir,
                database_url=database_url,
                admin_username=admin_username,
                vma_registry=vma_registry,
                vma_model=vma_model,
                vma_validation_sites=tuple(validation_site) if validation_site else None,
                vma_validation_reconstructed=(
                    tuple(validation_reconstructed) if validation_reconstructed else None
                ),
                review_url=review_url,
            )
        )
    except ValueError as error:
        raise bad_input(error) from error
    app = create_app(settings)
    gc.collect()
    gc.freeze()  # start-up objects live as long as the server: keep full collections (GIL held) off them
    quiet_change_polls("uvicorn.access")  # the 3D review's polls every 2 s would fill the access log
    run_server(app, host=host, port=port, log_level="info", access_log=ACCESS_LOG)


def run_server(app: Any, *, host: str, port: int, **options: Any) -> None:
    """`uvicorn.run`; a server that cannot start (its port taken, an address not of this machine) exits with code 1
    and an `error:` line naming the address, not with uvicorn's own code 3."""
    import uvicorn
    from uvicorn.config import STARTUP_FAILURE

    try:
        uvicorn.run(app, host=host, port=port, **options)
    except SystemExit as stop:
        if stop.code != STARTUP_FAILURE:
            raise
        raise failure(f"the server could not start on {host}:{port} (its log above says why)") from None
