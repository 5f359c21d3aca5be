"""`cama segment` (masks for a data set without its own), `cama train-segmenter` (the network behind it) and
`cama calibrate-segmenter` (its per-class logit offsets, fitted on fresh sites)."""

import dataclasses
import logging
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from cama_pipeline.cli_options import DatasetArg, OverwriteOpt, ScenesOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.segment.calibrate import CalibrationConfig, calibrate
from cama_pipeline.segment.checkpoint import read_meta
from cama_pipeline.segment.config import NetworkConfig, SegmentConfig, TrainConfig
from cama_pipeline.segment.predict import resolve_device
from cama_pipeline.segment.stage import EXECUTORS, run
from cama_pipeline.segment.train import train

logger = logging.getLogger(__name__)

DeviceOpt = Annotated[str, typer.Option(help="auto (CUDA when present, else CPU), cpu or cuda.")]


def segment_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    checkpoint: Annotated[
        Path | None,
        typer.Option(help="Segmenter checkpoint folder; default: the one shipped with the package."),
    ] = None,
    batch_size: Annotated[int, typer.Option(min=1, help="Images per network call.")] = 8,
    executor: Annotated[
        str, typer.Option(help="Where batches run: local (this process or a process pool) or ray.")
    ] = "local",
    workers: Annotated[int, typer.Option(min=1, help="Processes segmenting at once (CPU).")] = 2,
    device: DeviceOpt = "auto",
    flip_average: Annotated[
        bool,
        typer.Option(
            help="Average each image's class probabilities with its mirror image's (twice the network's cost; "
            "--no-flip-average halves it)."
        ),
    ] = SegmentConfig().flip_average,
    scene: ScenesOpt = None,
    overwrite: OverwriteOpt = False,
) -> None:
    """Predict semantic masks and lane instances for every image the pipeline uses, into the workspace's
    masks/predicted/ (the data set is left as it is); `--masks predicted` (or auto) then reads them."""
    try:
        if executor not in EXECUTORS:
            raise ValueError(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
        config = SegmentConfig(
            checkpoint=checkpoint,
            batch_size=batch_size,
            device=device,  # type: ignore[arg-type]
            flip_average=flip_average,
        )
        result = run(
            config, dataset, workspace, executor=executor, workers=workers, scenes=scene, overwrite=overwrite
        )
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    (item,) = result.items
    report = item.report
    state = (
        "up to date"
        if item.skipped
        else f"{report['segmented']} segmented, {report['reused']} kept, {result.seconds:.1f} s"
    )
    console.print(
        f"[green]predicted masks[/green] for {len(report['images'])} images with "
        f"{report['made_by']['checkpoint']} ({state})"
    )
    console.print(f"  -> {item.path}")


def _iou_table(title: str, per_class: dict[str, float | None]) -> Table:
    """A one-row table of per-class IoU (- for a class neither present nor predicted)."""
    table = Table(title=title)
    for name in per_class:
        table.add_column(name)
    table.add_row(*("-" if v is None else f"{v:.3f}" for v in per_class.values()))
    return table


def _network_config(full_resolution_width: int | None, init: Path | None) -> NetworkConfig | None:
    """The network `cama train-segmenter` asks for: None (the --init checkpoint's, else the default) unless
    `--full-resolution-width` is given, then the init checkpoint's (or the default) config with that width."""
    if full_resolution_width is None:
        return None
    base = NetworkConfig.from_json(read_meta(init)["network"]) if init is not None else NetworkConfig()
    return dataclasses.replace(base, full_resolution_width=full_resolution_width)


def train_segmenter_command(
    sites: Annotated[
        list[Path],
        typer.Option(
            "--sites", help="Generated site folders, or folders of them (repeatable); randomised sites."
        ),
    ],
    out: Annotated[Path, typer.Option(help="Checkpoint folder to write (replaced if there).")],
    held_out: Annotated[
        list[Path] | None,
        typer.Option("--held-out", help="Sites to report per-class IoU on (never trained on; repeatable)."),
    ] = None,
    epochs: Annotated[int, typer.Option(min=1, help="Passes over the training images.")] = 12,
    batch_size: Annotated[int, typer.Option(min=1, help="Crops per step.")] = 8,
    learning_rate: Annotated[float, typer.Option(help="Peak learning rate (one-cycle).")] = 3e-3,
    threads: Annotated[int, typer.Option(min=1, help="torch CPU threads.")] = 2,
    seed: Annotated[int, typer.Option(help="Seed of the crops, augmentations and initial weights.")] = 0,
    device: DeviceOpt = "auto",
    label: Annotated[
        str | None, typer.Option(help="Name recorded in the checkpoint (default: folder).")
    ] = None,
    init: Annotated[
        Path | None,
        typer.Option(
            help="Go on training this checkpoint (its training sites count as seen by the new one)."
        ),
    ] = None,
    full_resolution_width: Annotated[
        int | None,
        typer.Option(
            min=0,
            help="Channels of the stride-1 refinement (0: none). Default: the --init checkpoint's, else "
            f"{NetworkConfig().full_resolution_width}. A checkpoint without one may go on with one.",
        ),
    ] = None,
    max_class_weight: Annotated[
        float,
        typer.Option(help="Cap of the cross-entropy class weights (inverse square-root frequencies)."),
    ] = TrainConfig().max_class_weight,
    scale_range: Annotated[
        tuple[float, float],
        typer.Option(
            help="Range of the random rescale of each training image before its crop (LOW HIGH; 1 1 keeps the "
            "images' own scale, so no mask is resampled)."
        ),
    ] = TrainConfig().scale_range,
    paint_fade_max: Annotated[
        float,
        typer.Option(
            help="Extra paint wear: half the crops have their markings faded toward the road by a share drawn "
            "in [0, this] (0: none)."
        ),
    ] = TrainConfig().paint_fade_max,
    crop: Annotated[
        tuple[int, int],
        typer.Option(
            help="Training crop HEIGHT WIDTH in pixels (multiples of 32) of the input-width images."
        ),
    ] = (TrainConfig().crop_height_px, TrainConfig().crop_width_px),
    loader_workers: Annotated[
        int,
        typer.Option(
            min=0, help="Processes making the augmented crops beside training (0: the loop itself)."
        ),
    ] = 0,
    time_budget: Annotated[
        float | None,
        typer.Option(
            help="Seconds to train for instead of --epochs passes (the schedule fills them; the checkpoint "
            "records the passes made)."
        ),
    ] = None,
) -> None:
    """Train the segmentation network on randomised generator sites (never on a measurement site) and write a
    checkpoint that records its config, the sites it saw and its per-class IoU on the held-out sites."""
    try:
        config = TrainConfig(
            epochs=epochs,
            batch_size=batch_size,
            learning_rate=learning_rate,
            threads=threads,
            seed=seed,
            max_class_weight=max_class_weight,
            scale_range=scale_range,
            paint_fade_max=paint_fade_max,
            crop_height_px=crop[0],
            crop_width_px=crop[1],
            loader_workers=loader_workers,
            time_budget_s=time_budget,
        )
        folder = train(
            config,
            sites,
            out,
            held_out=held_out or [],
            network=_network_config(full_resolution_width, init),
            init=init,
            device=resolve_device(device),
            label=label,
        )
        meta = read_meta(folder)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    held = meta["metrics"].get("held_out")
    if held:
        console.print(_iou_table(f"held-out IoU ({held['images']} images)", held["per_class_iou"]))
    console.print(
        f"[green]trained[/green] on {meta['images']} images of {len(meta['training_sites'])} sites in "
        f"{meta['seconds']:.0f} s; {meta['metrics']['cpu_seconds_per_512x288']:.3f} s per 512x288 image on one "
        "CPU thread"
    )
    console.print(f"  -> {folder}")


def calibrate_segmenter_command(
    sites: Annotated[
        list[Path],
        typer.Option(
            "--sites",
            help="Generated site folders, or folders of them (repeatable): randomised sites the checkpoint "
            "never saw, not measurement sites.",
        ),
    ],
    out: Annotated[Path, typer.Option(help="Calibrated checkpoint folder to write (replaced if there).")],
    checkpoint: Annotated[
        Path | None, typer.Option(help="Checkpoint to calibrate; default: the one shipped with the package.")
    ] = None,
    held_out: Annotated[
        list[Path] | None,
        typer.Option("--held-out", help="Sites to report the calibrated per-class IoU on (repeatable)."),
    ] = None,
    device: DeviceOpt = "auto",
    label: Annotated[
        str | None, typer.Option(help="Name recorded in the checkpoint (default: folder).")
    ] = None,
    classes: Annotated[
        str,
        typer.Option(
            help="Comma-separated classes whose offsets are fitted, e.g. background,road,curb,lane_marking,"
            "crosswalk; the others keep 0. Empty: every class."
        ),
    ] = "",
) -> None:
    """Fit one logit offset per class on fresh sites' images (undoing the class-weighted loss's pull toward
    thin classes) and write the calibrated checkpoint, which counts those sites as seen."""
    try:
        config = CalibrationConfig(classes=tuple(name.strip() for name in classes.split(",") if name.strip()))
        folder = calibrate(
            sites,
            out,
            checkpoint=checkpoint,
            held_out=held_out or [],
            config=config,
            device=resolve_device(device),
            label=label,
        )
        meta = read_meta(folder)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    record = meta["calibration"]
    console.print(
        _iou_table(f"calibration images ({record['images']}), before", record["before"]["per_class_iou"])
    )
    console.print(_iou_table("after", record["after"]["per_class_iou"]))
    held = meta["metrics"].get("held_out")
    if held:
        console.print(_iou_table(f"held-out IoU ({held['images']} images)", held["per_class_iou"]))
    console.print(f"[green]calibrated[/green] offsets {record['offsets']} in {record['seconds']:.0f} s")
    console.print(f"  -> {folder}")
