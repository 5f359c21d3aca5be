"""`cama demo`: load a generated site and its VMA proposals into a backend database, then serve the editor
(and the viser 3D review beside it, linked from the editor's top bar).

With `--rasters <workspace>/surface/<site_id>/bev` the editor shows the reconstructed BEV rasters (the proposals
made from them share their frame); without it, the generator's ground-truth rasters. The demo server keeps its
database in `--data-dir`; a rerun reuses it (the site and its proposals are loaded once, so people's edits survive
restarts). Three demo accounts are made on first run, one per role, with the password from CAMA_DEMO_PASSWORD
(default `cama-demo`): they are printed with the URL.
"""

import logging
import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from sqlalchemy import select
from sqlalchemy.orm import Session

from annotations.schema import AnnotationSet
from app.backend import crud
from app.backend.config import Settings
from app.backend.errors import InvalidInputError
from app.backend.models import Site, User
from app.backend.schemas import ElementCreate, GeoreferenceIn, SiteCreate
from app.backend.vma_loop import with_shipped_registry
from cama_pipeline.bev import read_georeference
from cama_pipeline.console import bad_input
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)
DEMO_USERS = (("admin", "admin"), ("lead", "lead"), ("annotator", "annotator"))
DEFAULT_PASSWORD = "cama-demo"
WILDCARD_HOSTS = ("0.0.0.0", "::", "")


def ensure_demo_users(session: Session, password: str, scrypt_n: int) -> None:
    """One account per role, made only when missing."""
    for username, role in DEMO_USERS:
        if session.scalar(select(User).where(User.username == username)) is None:
            crud.create_user(
                session=session, username=username, password=password, role=role, scrypt_n=scrypt_n
            )


def read_proposals(proposals: Path) -> AnnotationSet:
    """The proposals file; InvalidInputError naming it when unreadable."""
    try:
        return AnnotationSet.read_json(proposals)
    except (OSError, ValueError) as err:
        raise InvalidInputError("proposals", f"{proposals}: {err}") from None


def site_request(site_dir: Path, rasters: Path | None, proposals: Path | None, name: str) -> SiteCreate:
    """The synthetic site with its ground-truth rasters, or with a reconstructed raster folder (in the frame
    of the proposals made from it: their site origin, else the raster's own origin)."""
    if rasters is None:
        return SiteCreate(name=name, synthetic_dir=str(site_dir))
    try:
        georeference = GeoreferenceIn.of(read_georeference(rasters))
    except (OSError, ValueError) as err:
        raise InvalidInputError("rasters", str(err)) from None
    origin = read_proposals(proposals).georeference.site_origin_xy if proposals else georeference.origin_xy
    return SiteCreate(name=name, site_origin_xy=origin, georeference=georeference, raster_dir=str(rasters))


def load_site(
    session: Session,
    site_dir: Path,
    proposals: Path | None,
    name: str,
    *,
    margin_m: float,
    roots: Sequence[Path],
    rasters: Path | None = None,
) -> tuple[Site, int]:
    """Register the site (once) and bulk-load its proposals (once); returns the site and how many were loaded."""
    existing = session.scalar(select(Site).where(Site.name == name))
    if existing is not None:
        return existing, 0
    site_in = site_request(site_dir, rasters, proposals, name)
    site = crud.create_site(session=session, site_in=site_in, roots=roots)
    if proposals is None:
        return site, 0
    annotation_set = read_proposals(proposals)
    elements = [
        ElementCreate(
            cls=e.cls,
            points=list(e.points_2d),
            confidence=e.confidence,
            source="proposal",
            model=e.author or None,
        )
        for e in annotation_set.elements
    ]
    if elements:
        crud.create_elements(
            session=session, site_id=site.id, elements_in=elements, username="vma", margin_m=margin_m
        )
    return site, len(elements)


def demo_command(
    site_dir: Annotated[Path, typer.Argument(help="A site folder written by `cama synth`.")] = Path(
        "data/synthetic/default"
    ),
    proposals: Annotated[
        Path | None, typer.Option(help="Proposals JSON from `cama propose` to load into the site.")
    ] = None,
    data_dir: Annotated[Path, typer.Option(help="The demo server's database and tiles.")] = Path(
        "data/demo-server"
    ),
    rasters: Annotated[
        Path | None,
        typer.Option(
            help="Reconstructed raster folder (<workspace>/surface/<site_id>/bev) to show instead of the ground truth."
        ),
    ] = None,
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="TCP port.")] = 8000,
    view_port: Annotated[
        int, typer.Option(min=0, max=65535, help="Port of the viser 3D review beside the editor; 0: none.")
    ] = 8080,
) -> None:
    """Load the site and its proposals into the backend and serve the editor (Ctrl+C stops it)."""
    from app.backend.main import create_app
    from app.backend.serve import run_server

    password = os.environ.get("CAMA_DEMO_PASSWORD", DEFAULT_PASSWORD)
    # the operator's own paths are checked here, by name; the API's data-roots rule hides them from its callers
    for label, folder in (("SITE_DIR", site_dir), ("--rasters", rasters)):
        if folder is not None and not folder.is_dir():
            raise bad_input(f"{label}: {folder}: not a folder")
    if proposals is not None and not proposals.is_file():
        raise bad_input(f"--proposals: {proposals}: not a file")
    try:
        settings = with_shipped_registry(demo_settings(data_dir, site_dir, rasters))
    except ValueError as err:  # a bad CAMA_* variable; a data folder whose vma-registry is not a registry
        raise bad_input(err) from err
    app = create_app(settings)
    try:
        with app.state.sessionmaker() as session:
            ensure_demo_users(session, password, settings.scrypt_n)
            name = site_dir.resolve().name + (" (reconstructed)" if rasters else "")
            site, loaded = load_site(
                session,
                site_dir,
                proposals,
                name,
                margin_m=settings.extent_margin_m,
                roots=settings.allowed_data_roots,
                rasters=rasters,
            )
            site_id = site.id
    except InvalidInputError as err:
        raise bad_input(f"{err.field}: {err.message}") from err
    url = f"http://{host}:{port}/"
    typer.echo(f"site {site_dir} loaded as site {site_id}" + (f" with {loaded} proposals" if loaded else ""))
    typer.echo(f"editor: {url}#/site/{site_id}   API docs: {url}docs")
    typer.echo(
        f"log in as annotator, lead or admin; password {password!r} (set CAMA_DEMO_PASSWORD to change)"
    )
    if view_port:
        try:
            workspace, site_key = review_site(site_dir, rasters)
        except ValueError as err:  # rasters outside a workspace: the editor shows them, the review cannot
            typer.echo(f"3D review not started: {err}", err=True)
        else:
            _start_review(
                site_dir, workspace, site_key, site_id, password, f"http://{host}:{port}", host, view_port
            )
            # the review's site is known only once loaded; the editor's link reads these two fields per request
            app.state.settings = replace(
                settings, review_url=review_url(host, view_port), review_site_id=site_id
            )
    run_server(app, host=host, port=port, log_level="warning")


def demo_settings(data_dir: Path, site_dir: Path, rasters: Path | None) -> Settings:
    """The CAMA_* settings (as `cama serve` reads them) on the demo's data folder, with the demo's site folder
    and raster folder added to the data roots (CAMA_DATA_ROOTS, else the data folder)."""
    settings = Settings.from_env(data_dir=data_dir)
    folders = (site_dir, *([rasters] if rasters is not None else []))
    return replace(settings, data_roots=(*settings.allowed_data_roots, *(f.resolve() for f in folders)))


def review_url(host: str, port: int) -> str:
    """The 3D review's URL for the editor's link: `:<port>` (the browser's host) when listening on every
    address, since the browser reaches the machine by a name the server does not know."""
    return f":{port}" if host in WILDCARD_HOSTS else f"http://{host}:{port}/"


def review_site(site_dir: Path, rasters: Path | None) -> tuple[Workspace, str | None]:
    """The workspace and site the 3D review shows: those of `--rasters` (`<workspace>/surface/<site_id>/bev`;
    ValueError naming it when it is not such a folder), else the site folder's own workspace (`<site>/workspace`)
    and its first site (None)."""
    if rasters is not None:
        return Workspace.locate(rasters)
    return Workspace.for_dataset(site_dir / "nuscenes"), None


def _start_review(
    site_dir: Path,
    workspace: Workspace,
    site_key: str | None,
    site_id: int,
    password: str,
    api: str,
    host: str,
    port: int,
) -> None:
    """The viser 3D review of the demo site (`site_key` of `workspace`; None: its first site), following the
    demo server's vectors (site `site_id`, as the lead)."""
    from app.viewer.review import ViewInputs, serve_in_background
    from app.viewer.sources import ApiVectorSource

    inputs = ViewInputs(site_dir, workspace.root, site_key)
    serve_in_background(inputs, ApiVectorSource(api, site_id, "lead", password), host=host, port=port)
    typer.echo(f"3D review: http://{host}:{port}/")
