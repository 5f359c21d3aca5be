"""`cama scenes`: list a data set's scenes (name, location, samples, duration, description) to choose a run's."""

import json
from collections import Counter
from typing import Annotated

import typer

from cama_pipeline.cli_options import DatasetArg
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.data.scene_list import scene_summaries


def scenes_command(
    dataset: DatasetArg,
    location: Annotated[str | None, typer.Option(help="Only the scenes of this log.location.")] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="One JSON list on stdout instead of lines.")
    ] = False,
) -> None:
    """List the data set's scenes from its small tables (seconds even for nuScenes v1.0-trainval), to pick the
    `--scene`s of `cama run`; a site never joins scenes of two locations."""
    try:
        summaries = scene_summaries(dataset, location=location)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    if as_json:
        console.out(json.dumps([s.to_json() for s in summaries], indent=1), highlight=False)
        return
    for s in summaries:
        console.print(
            f"{s.name}  {s.location}  {s.samples} samples, {s.duration_s:.1f} s, {s.date_captured}  "
            f"CAN {'+'.join(s.can_bus) or 'none'}  {s.description}",
            highlight=False,
            markup=False,
        )
    locations = Counter(s.location for s in summaries)
    counts = ", ".join(f"{name} {count}" for name, count in sorted(locations.items()))
    console.print(f"{len(summaries)} scenes" + (f" ({counts})" if counts else ""), highlight=False)
