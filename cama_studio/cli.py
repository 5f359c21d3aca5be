"""The `cama` command line: one sub-command per pipeline stage, each a thin layer over the stage's `run`."""

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from cama_pipeline.console import bad_input, console

if TYPE_CHECKING:
    from cama_pipeline.synthetic.config import SynthConfig
    from cama_pipeline.synthetic.generate import SynthResult

app = typer.Typer(
    help="CAMA Studio: consistent, accurate 3D HD-map annotation from surround-view video.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)


@app.callback()
def main(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Show debug logging.")] = False,
) -> None:
    """Configure logging for every command."""
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s"
    )


@app.command()
def synth(
    out: Annotated[
        Path, typer.Option(help="Site folder to write (nuscenes/ + ground_truth/ inside).")
    ] = Path("data/synthetic/default"),
    preset: Annotated[
        str, typer.Option(help="tiny (tests), default (demo) or large (benchmarks).")
    ] = "default",
    seed: Annotated[int | None, typer.Option(help="Random seed; the preset's when omitted.")] = None,
    workers: Annotated[int, typer.Option(min=1, help="Render processes.")] = 2,
    overwrite: Annotated[bool, typer.Option(help="Regenerate even if the site is up to date.")] = False,
    images: Annotated[
        bool,
        typer.Option(help="Render camera images and masks; --no-images writes tables and ground truth only."),
    ] = True,
    degrade_masks: Annotated[
        bool | None,
        typer.Option(
            help="Force mask degradation on (jitter 2 px, 5% missed markings) or off; the preset's when omitted."
        ),
    ] = None,
    random_seed: Annotated[
        int | None,
        typer.Option(
            min=0,
            help="Draw a randomised site (layout, terrain, look, paint wear, light, camera) from this seed, the "
            "size of --preset; its location is synth-random-SEED. Not with --seed.",
        ),
    ] = None,
    masks: Annotated[
        bool,
        typer.Option(
            help="Masks in the data set; --no-masks writes a data set as real nuScenes is: no semantic/ and "
            "lane_instance/ (they go to ground_truth/ for evaluation, exact: no mask degradation) and no GNSS CAN "
            "file."
        ),
    ] = True,
    logged_height: Annotated[
        bool,
        typer.Option(
            help="Logged ego poses with their heights; --no-logged-height writes z = 0 in every ego_pose, as "
            "nuScenes' 2D localization does (with --no-masks: nuScenes as it really is). The truth keeps them.",
        ),
    ] = True,
    image_size: Annotated[
        str | None,
        typer.Option(
            metavar="WxH",
            help="Camera image size in pixels, e.g. 1600x900 (nuScenes' own); the preset's when omitted. "
            "Intrinsics scale with it; render time grows with the pixel count.",
        ),
    ] = None,
    terrain_rise: Annotated[
        float | None,
        typer.Option(
            metavar="M",
            help="Total rise in metres of the terrain's ramp along the main road (either sign); the preset's "
            "when omitted (tiny 2, default 4, large 6). A larger rise starts the drives metres apart in height, "
            "as on a hilly city's logs.",
        ),
    ] = None,
    ramp_width: Annotated[
        float | None,
        typer.Option(
            metavar="M",
            help="Width in metres of that ramp (its steepest grade is rise / (2 width), kept within 9 % with "
            "the cross slope and waves); the preset's when omitted (tiny 25, default 45, large 70).",
        ),
    ] = None,
) -> None:
    """Generate a synthetic driving site in nuScenes layout, with its ground truth kept beside it."""
    from cama_pipeline.synthetic.generate import run

    if seed is not None and random_seed is not None:
        raise bad_input(
            "--seed and --random-seed exclude each other (a randomised site uses its random seed)"
        )
    if degrade_masks and not masks:
        raise bad_input(
            "--degrade-masks and --no-masks exclude each other (a mask-free site's masks are its ground truth, "
            "written exact)"
        )
    try:
        cfg = _synth_config(preset, seed, random_seed, degrade_masks, image_size, (terrain_rise, ramp_width))
        result = run(
            cfg,
            out,
            images=images,
            masks=masks,
            gnss=masks,
            logged_height=logged_height,
            overwrite=overwrite,
            workers=workers,
        )
    except (ValueError, FileExistsError) as err:
        raise bad_input(err) from err
    _print_site(result, cfg)


def _synth_config(
    preset: str,
    seed: int | None,
    random_seed: int | None,
    degrade_masks: bool | None,
    image_size: str | None,
    ramp: tuple[float | None, float | None] = (None, None),
) -> "SynthConfig":
    """The config `cama synth`'s options ask for (ValueError for a bad preset, size or value); `ramp`: the
    terrain ramp's rise and width, None keeping the preset's (or the randomised draw's)."""
    from dataclasses import replace

    from cama_pipeline.synthetic.config import MaskNoiseConfig, parse_image_size, with_ramp
    from cama_pipeline.synthetic.config import preset as make_preset
    from cama_pipeline.synthetic.randomise import randomised_config

    overrides: dict[str, object] = {}
    if seed is not None:
        overrides["seed"] = seed
    if degrade_masks is not None:
        overrides["masks"] = MaskNoiseConfig(2, 0.05) if degrade_masks else MaskNoiseConfig()
    if random_seed is not None:
        cfg = replace(randomised_config(random_seed, base=preset), **overrides)  # type: ignore[arg-type]
    else:
        cfg = make_preset(preset, **overrides)
    if image_size is not None:
        width, height = parse_image_size(image_size)
        cfg = replace(cfg, camera=replace(cfg.camera, width_px=width, height_px=height))
    if ramp != (None, None):
        cfg = replace(cfg, terrain=with_ramp(cfg.terrain, *ramp))
    return cfg


def _print_site(result: "SynthResult", cfg: "SynthConfig") -> None:
    """What `cama synth` made (or found up to date) and where."""
    state = "up to date, nothing generated" if result.skipped else f"generated in {result.seconds:.0f} s"
    console.print(f"[green]site[/green] {result.out_dir} ({state})")
    console.print(f"  data set (nuScenes layout): {result.dataset_root}  version {result.version}")
    if cfg.random_seed is not None:
        console.print(
            f"  randomised site {cfg.random_seed} (location {cfg.log_location}), config in the manifest"
        )
    console.print(f"  ground truth:               {result.ground_truth_dir}")
    kinds = ", ".join(f"{name} ({kind})" for name, kind in result.scenes.items())
    console.print(f"  {len(result.scenes)} scenes: {kinds}")
    size = f"{cfg.camera.width_px}x{cfg.camera.height_px}"
    if not result.images_rendered:
        console.print(
            f"  {result.images} camera images listed, NOT rendered (--no-images): no image or mask files"
        )
    elif result.masks_in_dataset:
        console.print(f"  {result.images} camera images ({size}) with semantic and lane-instance masks")
    else:
        console.print(
            f"  {result.images} camera images ({size}); no masks in the data set (--no-masks): they are in "
            f"{result.mask_root}"
        )
    if not result.gnss:
        console.print("  no GNSS CAN files (as real nuScenes)")
    if not result.logged_height:
        console.print("  logged ego poses without heights: z = 0 (as real nuScenes)")


def _register_stage_commands() -> None:
    """Commands whose implementation lives beside their stage (imported here, registered by name)."""
    from app.backend.serve import serve_command
    from app.demo import demo_command
    from app.viewer.command import view_command
    from cama_pipeline.data.command import scenes_command
    from cama_pipeline.evaluate.command import eval_command
    from cama_pipeline.features.command import features_command
    from cama_pipeline.keyframes.command import keyframes_command
    from cama_pipeline.pairs.command import pairs_command
    from cama_pipeline.segment.command import (
        calibrate_segmenter_command,
        segment_command,
        train_segmenter_command,
    )
    from cama_pipeline.segment.import_masks import import_masks_command
    from cama_pipeline.sfm.command import sfm_command
    from cama_pipeline.site.command import sites_command
    from cama_pipeline.surface.command import surface_command
    from cama_pipeline.wigo.command import wigo_command
    from cama_studio.export_command import export_command, import_command
    from cama_studio.run_command import run_command
    from models.vma.commands import (
        propose_command,
        retrain_command,
        train_command,
        vma_eval_command,
        vma_split_command,
    )
    from models.vma.element_masks.commands import train_masks_command

    app.command("eval")(eval_command)
    app.command("export")(export_command)
    app.command("import")(import_command)
    app.command("serve")(serve_command)
    app.command("demo")(demo_command)
    app.command("view")(view_command)
    app.command("scenes")(scenes_command)
    app.command("wigo")(wigo_command)
    app.command("keyframes")(keyframes_command)
    app.command("sites")(sites_command)
    app.command("pairs")(pairs_command)
    app.command("segment")(segment_command)
    app.command("import-masks")(import_masks_command)
    app.command("features")(features_command)
    app.command("surface")(surface_command)
    app.command("sfm")(sfm_command)
    app.command("propose")(propose_command)
    app.command("run")(run_command)
    app.command("train")(train_command)
    app.command("retrain")(retrain_command)
    app.command("train-masks")(train_masks_command)
    app.command("vma-eval")(vma_eval_command)
    app.command("vma-split")(vma_split_command)
    app.command("train-segmenter")(train_segmenter_command)
    app.command("calibrate-segmenter")(calibrate_segmenter_command)


_register_stage_commands()

if __name__ == "__main__":
    app()
