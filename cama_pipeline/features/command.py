"""`cama features`: masked SIFT of every keyframe image and matching on the selected pairs."""

from typing import Annotated

import typer

from cama_pipeline.cli_options import DatasetArg, MasksOpt, OverwriteOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.stage import run


def features_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    max_features: Annotated[int, typer.Option(help="SIFT keypoints per image at most.")] = 4096,
    mask_dilation_px: Annotated[
        int, typer.Option(help="Growth of the vehicle / ego-body masks, pixels.")
    ] = 9,
    threads: Annotated[int, typer.Option(help="Extraction and matching threads.")] = 2,
    matcher: Annotated[
        str,
        typer.Option(
            help="Descriptor matcher: blas (matrix products, fast) or colmap (COLMAP's CPU matcher)."
        ),
    ] = "blas",
    masks: MasksOpt = "auto",
    overwrite: OverwriteOpt = False,
) -> None:
    """Extract masked SIFT into each site's COLMAP database and match the pairs from `cama pairs`."""
    try:
        config = FeaturesConfig(
            max_num_features=max_features,
            mask_dilation_px=mask_dilation_px,
            num_threads=threads,
            matcher=matcher,  # type: ignore[arg-type]  # checked by FeaturesConfig
        )
        result = run(config, dataset, workspace, masks=masks, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    for site in result.items:
        report = site.report
        counts = [c["features"] for c in report["images"].values()]
        mean = sum(counts) / max(len(counts), 1)
        console.print(
            f"[green]{site.name}[/green]: {len(counts)} images, {mean:.0f} features each on average, "
            f"{report['pairs_verified']} of {report['pairs_listed']} pairs verified "
            f"(median {report['median_inliers']} inliers) -> {result.workspace.features_db(site.name)}"
        )
        if report["low_feature_images"]:
            console.print(
                f"  [yellow]{len(report['low_feature_images'])} image(s) with few features[/yellow]"
            )
