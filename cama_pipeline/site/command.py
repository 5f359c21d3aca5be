"""`cama sites`: aggregate the scenes of a data set into sites and write the site manifests."""

from typing import Annotated

import typer

from cama_pipeline.cli_options import DatasetArg, OverwriteOpt, ScenesOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.stage import run


def sites_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    scene: ScenesOpt = None,
    overlap_radius_m: Annotated[float, typer.Option(help="Scenes closer than this share a site.")] = 30.0,
    night_brightness: Annotated[
        float, typer.Option(help="Mean 8-bit luma below which a scene counts as night.")
    ] = 60.0,
    overwrite: OverwriteOpt = False,
) -> None:
    """Group overlapping scenes of one location into sites, drop night scenes, merge stationary clips (after wigo,
    keyframes)."""
    try:
        config = SiteConfig(overlap_radius_m=overlap_radius_m, night_brightness=night_brightness)
        result = run(config, dataset, workspace, scenes=scene, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    for site in result.items:
        state = " (up to date)" if site.skipped else ""
        merged = ", ".join(f"{s} -> {m}" for s, m in site.report["merged"].items()) or "none"
        console.print(
            f"[green]{site.name}[/green]{state} ({site.report['location']}): {', '.join(site.report['scenes'])}; "
            f"merged: {merged}"
        )
        console.print(f"  manifest: {site.path}")
    for dropped in result.report["dropped"]:
        console.print(f"[yellow]dropped[/yellow] {dropped['scene']}: {dropped['reason']}")
