"""`cama eval`: SRE / precision / recall / F1 of a vector map over a data set, printed and written as JSON."""

import logging
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from cama_pipeline.cli_options import DatasetArg, MasksOpt, WorkspaceOpt
from cama_pipeline.console import bad_input, console
from cama_pipeline.data import DatasetError, load_dataset, mask_roots
from cama_pipeline.evaluate.inputs import EvaluationInputError, load_true_poses, load_vector_map
from cama_pipeline.evaluate.projection import ProjectionConfig
from cama_pipeline.evaluate.sre import SreConfig
from cama_pipeline.evaluate.sre_cama_config import SreProtocol
from cama_pipeline.evaluate.sre_dataset import evaluate_sre
from cama_pipeline.evaluate.sre_report import SreReport, SreSummary
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import Semantic

logger = logging.getLogger(__name__)


class ProtocolChoice(StrEnum):
    """Which metric rules score the map."""

    strict = "strict"
    cama = "cama"


PROTOCOL_LINES: dict[SreProtocol, str] = {
    "strict": "protocol: strict (the project's own: every camera with lanes counts, every skeleton pixel measured)",
    "cama": "protocol: cama (CAMA's published metric code: cameras without a match left out, spline normals,"
    " frame 0 skipped, 960x540)",
}
"""The printed line naming the protocol of a report."""


class PoseSource(StrEnum):
    """Which ego poses project the map."""

    true = "true"
    coarse = "coarse"


def eval_command(
    dataset: DatasetArg,
    vector_map: Annotated[
        Path, typer.Argument(help="Vector map JSON ({'elements': [...]}, 3D or 2D points).")
    ],
    out: Annotated[Path, typer.Option(help="Where to write the JSON report.")] = Path("sre_report.json"),
    poses: Annotated[
        PoseSource, typer.Option(help="true (needs --true-poses) or coarse (the logged ego_pose).")
    ] = PoseSource.coarse,
    true_poses: Annotated[
        Path | None, typer.Option(help="Ground-truth poses.json (for --poses true).")
    ] = None,
    protocol: Annotated[
        ProtocolChoice,
        typer.Option(
            help="strict (the project's own rules) or cama (the rules of CAMA's published metric code)."
        ),
    ] = ProtocolChoice.strict,
    boundaries: Annotated[
        bool, typer.Option(help="Also match boundaries against curb instances (strict protocol only).")
    ] = False,
    scene: Annotated[list[str] | None, typer.Option(help="Evaluate only this scene (repeatable).")] = None,
    gate_px: Annotated[
        float, typer.Option(help="Matching gate in pixels at 960 px width (strict protocol).")
    ] = 30.0,
    range_m: Annotated[
        float, typer.Option(help="Crop the map to this distance from each camera (strict protocol).")
    ] = 50.0,
    masks: MasksOpt = "auto",
    workspace: WorkspaceOpt = None,
) -> None:
    """Semantic reprojection error (CAMAv2 Algorithm 2) of a vector map against the image lane instances (the
    data set's own, or the workspace's with --masks)."""
    try:
        pairs = [("divider", int(Semantic.LANE_MARKING))] + (
            [("boundary", int(Semantic.CURB))] if boundaries else []
        )
        if protocol is ProtocolChoice.cama and boundaries:
            raise EvaluationInputError("--boundaries: the cama protocol scores lane markings only")
        config = SreConfig(
            protocol=protocol.value,
            class_pairs=tuple(pairs),
            gate_px=gate_px,
            projection=ProjectionConfig(range_m=range_m),
        )
        if poses is PoseSource.true and true_poses is None:
            raise EvaluationInputError("--poses true needs --true-poses PATH (the ground-truth poses.json)")
        pose_table = load_true_poses(true_poses) if poses is PoseSource.true and true_poses else None
        elements = load_vector_map(vector_map)
        data = load_dataset(dataset, mask_roots=mask_roots(masks, dataset, workspace))
        report = evaluate_sre(data, elements, config, true_poses=pose_table, scenes=scene, show_progress=True)
    except (EvaluationInputError, DatasetError, FileNotFoundError, ValueError) as err:
        raise bad_input(err) from err
    atomic_write_json(out, report.to_json(), indent=1)
    title = f"SRE of {vector_map.name} ({poses.value} poses, {protocol.value} protocol)"
    console.print(report_table(report, title))
    console.print(PROTOCOL_LINES[report.config.protocol])
    console.print(f"report written to {out}")


def report_table(report: SreReport, title: str) -> Table:
    """A rich table: overall, per scene and per camera rows."""
    table = Table(title=title)
    for name in (
        "",
        "SRE px",
        "SRE @960 px",
        "precision",
        "recall",
        "F1",
        "matched",
        "projected",
        "image inst.",
    ):
        table.add_column(name, justify="left" if not name else "right")
    rows = [("overall", report.overall)] + list(report.per_scene.items()) + list(report.per_camera.items())
    for name, summary in rows:
        table.add_row(name, *_cells(summary))
    return table


def _cells(summary: SreSummary) -> list[str]:
    """Formatted figures of one summary row."""
    figures = [summary.sre_px, summary.sre_ref_px, summary.precision, summary.recall, summary.f1]
    formatted = ["-" if v is None else f"{v:.2f}" if i < 2 else f"{v:.3f}" for i, v in enumerate(figures)]
    return formatted + [str(summary.matched), str(summary.projected), str(summary.image_instances)]
