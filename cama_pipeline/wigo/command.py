"""`cama wigo`: fuse wheel, IMU and GNSS (or, without GNSS, the logged ego pose) of every scene into ego poses at
the camera timestamps."""

from collections import Counter
from typing import Annotated

import typer

from cama_pipeline.cli_options import DatasetArg, OverwriteOpt, ScenesOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.wigo.config import RobustKernel, WigoConfig
from cama_pipeline.wigo.logged_only import NO_ODOMETRY
from cama_pipeline.wigo.stage import run


def wigo_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    scene: ScenesOpt = None,
    robust: Annotated[str, typer.Option(help="GNSS robust kernel: huber, cauchy or none.")] = "huber",
    logged_pose: Annotated[
        bool, typer.Option(help="Fuse the logged ego_pose too (off: wheel + IMU + GNSS only).")
    ] = True,
    overwrite: OverwriteOpt = False,
) -> None:
    """WIGO: pose-graph fusion of wheel + IMU + GNSS into 6-DoF ego poses with covariances."""
    try:
        kernel: RobustKernel = robust  # type: ignore[assignment]  # validated by WigoConfig
        sigmas = WigoConfig.logged_pose_sigmas if logged_pose else (0.0, 0.0, 0.0, 0.0)
        config = WigoConfig(gnss_robust=kernel, logged_pose_sigmas=sigmas)
        result = run(config, dataset, workspace, scenes=scene, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    done = len(result.items) - len(result.skipped)
    console.print(
        f"[green]wigo[/green] {done} scene(s) fused, {len(result.skipped)} up to date, "
        f"in {result.seconds:.1f} s -> {result.workspace.stage_dir('wigo')}"
    )
    constraints = Counter(str(item.report.get("global_constraint", "unrecorded")) for item in result.items)
    summary = ", ".join(f"{name} ({count} scene(s))" for name, count in sorted(constraints.items()))
    console.print(f"  global constraint: {summary}")
    passed = [item.name for item in result.items if item.report.get("odometry") == NO_ODOMETRY]
    if passed:
        console.print(
            f"  [yellow]no wheel speeds[/yellow], logged ego poses passed through: {', '.join(passed)}"
        )
