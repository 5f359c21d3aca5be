"""`cama view`: serve the 3D review of a site in viser until Ctrl+C."""

import threading
from pathlib import Path
from typing import Annotated

import typer

from cama_pipeline.console import bad_input, console


def view_command(
    site_dir: Annotated[Path, typer.Argument(help="A site folder written by `cama synth`.")] = Path(
        "data/synthetic/default"
    ),
    workspace: Annotated[
        Path | None, typer.Option(help="Workspace; default <site>/workspace (beside <site>/nuscenes).")
    ] = None,
    site_id: Annotated[
        str | None, typer.Option(help="Site of the workspace to show; default: its first site.")
    ] = None,
    annotations: Annotated[
        Path | None,
        typer.Option(
            help="Vectors from an annotation JSON file (default <workspace>/proposals/<site-id>.json, `cama run`'s)."
        ),
    ] = None,
    api: Annotated[
        str | None, typer.Option(help="Vectors from a running backend instead, e.g. http://127.0.0.1:8000.")
    ] = None,
    api_site: Annotated[int, typer.Option(help="The backend's site id.")] = 1,
    user: Annotated[str, typer.Option(help="Backend user.")] = "lead",
    password: Annotated[
        str, typer.Option(envvar="CAMA_VIEW_PASSWORD", help="Backend password.")
    ] = "cama-demo",
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="TCP port.")] = 8080,
    poll_s: Annotated[float, typer.Option(min=0.2, help="Seconds between vector refreshes.")] = 2.0,
) -> None:
    """Show the road mesh, lifted vectors by class and state, keyframe cameras and sparse points in 3D.

    The editor links here when the backend knows this URL (CAMA_REVIEW_URL; `cama demo` sets it), focused on
    the selected element (see app/viewer/focus.py)."""
    import viser

    from app.viewer.content import ViewInputError, first_site
    from app.viewer.review import ViewInputs, follow, open_review
    from app.viewer.sources import ApiVectorSource, FileVectorSource, VectorSource, VectorSourceError
    from cama_pipeline.io import WorkspaceError
    from cama_pipeline.workspace import Workspace

    input_errors = (ViewInputError, VectorSourceError, WorkspaceError, FileNotFoundError, ValueError)
    if not site_dir.is_dir():
        raise bad_input(f"SITE_DIR: {site_dir}: not a folder")
    ws = Workspace.resolve(workspace, site_dir / "nuscenes")
    try:
        site_id = site_id or first_site(ws.root)
        source: VectorSource = (
            ApiVectorSource(api, api_site, user, password)
            if api
            else FileVectorSource(annotations or ws.proposals(site_id))
        )
    except input_errors as err:
        raise bad_input(err) from err
    server = viser.ViserServer(host=host, port=port, label="CAMA Studio 3D review", verbose=False)
    try:
        scene = open_review(server, ViewInputs(site_dir, ws.root, site_id), source)
    except input_errors as err:
        server.stop()
        raise bad_input(err) from err
    # viser takes the next free port when `port` is busy
    console.print(f"3D review of {site_id}: http://{host}:{server.get_port()}  (Ctrl+C stops)")
    stop = threading.Event()
    try:
        follow(scene, source, stop, interval_s=poll_s)
    except KeyboardInterrupt:
        stop.set()
    finally:
        server.stop()
