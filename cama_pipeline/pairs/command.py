"""`cama pairs`: choose the image pairs to match for every site (sequential + homography-guided spatial pairs)."""

from typing import Annotated

import typer
from rich.table import Table

from cama_pipeline.cli_options import DatasetArg, OverwriteOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.io import PAIR_REASONS
from cama_pipeline.pairs.stage import run


def pairs_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    sequential_window: Annotated[
        int, typer.Option(help="Same-camera pairs up to this many keyframes apart.")
    ] = 3,
    knn: Annotated[
        int,
        typer.Option(
            help="Nearest cameras considered per image for spatial pairs; 0: all within the radius."
        ),
    ] = 0,
    knn_radius_m: Annotated[float, typer.Option(help="Spatial pairs are at most this far apart.")] = 40.0,
    max_dz_m: Annotated[
        float, typer.Option(help="Largest camera height difference of a spatial pair.")
    ] = 3.0,
    min_footprint_overlap: Annotated[
        float, typer.Option(help="Least shared ground (share of the larger footprint) of a spatial pair.")
    ] = 0.4,
    overwrite: OverwriteOpt = False,
) -> None:
    """Sequential and HSP pairs of each site's keyframe images (after `cama sites`)."""
    try:
        config = PairsConfig(
            sequential_window=sequential_window,
            knn=knn,
            knn_radius_m=knn_radius_m,
            max_dz_m=max_dz_m,
            min_footprint_overlap=min_footprint_overlap,
        )
        result = run(config, dataset, workspace, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    table = Table(title="pairs")
    kinds = ("exhaustive", *PAIR_REASONS, "total")
    for column in ("site", "images", *kinds, "share"):
        table.add_column(column)
    for site in result.items:
        counts = site.report["counts"]
        share = counts["total"] / max(counts["exhaustive"], 1)
        name = site.name + (" (up to date)" if site.skipped else "")
        values = [counts.get(k, 0) for k in kinds]
        table.add_row(name, str(site.report["images"]), *map(str, values), f"{share:.1%}")
    console.print(table)
    console.print(f"  -> {result.workspace.stage_dir('pairs')}")
