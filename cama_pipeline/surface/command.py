"""`cama surface`: road surface mesh and BEV rasters of every site (after `cama sites`, ideally `cama sfm`)."""

from typing import Annotated, Any

import typer
from rich.table import Table

from cama_pipeline.cli_options import DatasetArg, MasksOpt, OverwriteOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.surface.config import JointConfig, SurfaceConfig
from cama_pipeline.surface.stage import run


def surface_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    poses: Annotated[
        str,
        typer.Option(
            help="Pose source: sfm (after `cama sfm`, as `cama run` does), wigo (site manifest) or ground_truth."
        ),
    ] = "sfm",
    resolution_m: Annotated[float, typer.Option(help="Mesh vertex spacing and raster resolution.")] = 0.1,
    epochs: Annotated[
        int, typer.Option(help="Mesh optimisation passes over the keyframe images.")
    ] = SurfaceConfig.epochs,
    joint_epochs: Annotated[
        int,
        typer.Option(
            help="Passes of the joint optimisation by differentiable rendering (0: the vote alone)."
        ),
    ] = 0,
    refine_elevation: Annotated[
        bool, typer.Option(help="Refine the elevation MLP through the image losses.")
    ] = True,
    threads: Annotated[int, typer.Option(help="torch threads on the CPU.")] = 1,
    device: Annotated[str, typer.Option(help="auto, cpu or cuda.")] = "auto",
    masks: MasksOpt = "auto",
    overwrite: OverwriteOpt = False,
) -> None:
    """RoMe-style road surface: elevation MLP, mesh colour and semantics, BEV rasters per site."""
    try:
        config = SurfaceConfig(
            resolution_m=resolution_m,
            epochs=epochs,
            joint=JointConfig(epochs=joint_epochs),
            refine_elevation=refine_elevation,
            torch_threads=threads,
            device=device,  # type: ignore[arg-type]  # validated by SurfaceConfig
        )
        result = run(config, dataset, workspace, poses=poses, masks=masks, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    table = Table(title=f"surface ({poses} poses)")
    columns = (
        "site",
        "images",
        "vertices",
        "cells observed",
        "weakly observed road",
        "extrapolated road heights",
    )
    for column in (*columns, "seconds"):
        table.add_column(column)
    for site in result.items:
        report = site.report
        name = site.name + (" (up to date)" if site.skipped else "")
        seconds = sum(report["seconds"].values())
        weak = report["weak_observation"]
        weak_text = f"{100 * weak['road_weak_share']:.1f} % (< {weak['weak_rays']} rays; {weak['weak_regions']} regions)"
        values = (
            report["images"],
            report["vertices"],
            report["cells_observed"],
            weak_text,
            extrapolated_text(report.get("extrapolated_heights")),
            f"{seconds:.1f}",
        )
        table.add_row(name, *map(str, values))
    console.print(table)
    for site in result.items:  # paths on their own lines: a long one would crush the table
        console.print(f"  {site.name} -> {site.path}")


def extrapolated_text(extrapolated: dict[str, Any] | None) -> str:
    """The report's `extrapolated_heights` in a table cell ("-" for a report written before it existed)."""
    if extrapolated is None:
        return "-"
    share = 100 * extrapolated["extrapolated_road_share"]
    support = f"< {extrapolated['support_points']} points within {extrapolated['height_support_m']:g} m"
    return f"{share:.1f} % ({support}; up to {extrapolated['farthest_m']:g} m)"
