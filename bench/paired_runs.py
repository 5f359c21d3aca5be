"""What the benches that run the whole path twice on one site's variants share (`bench/logged_height.py`,
`bench/without_wheels.py`): the figures compared between the two runs, and how their results are written."""

import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

from cama_pipeline.io import atomic_write_json


def path_differences(reference: dict[str, Any], other: dict[str, Any]) -> dict[str, float]:
    """`other` minus `reference` for the figures a user of the export reads, of two runs measured by
    `bench/segment.py`'s `run_figures`."""

    def pick(run: dict[str, Any]) -> dict[str, float]:
        return {
            "sfm_gauge_free_position_cm": run["poses"]["sfm"]["gauge_free_position_cm"],
            "elevation_rmse_cm": run["elevation"]["rmse_cm"],
            "proposal_map": run["proposals_ap"]["observed_truth"]["mean_ap"],
            "sre_ref_px": run["sre"]["sre_ref_px"],
            "annotator_speed_up_in_reconstruction_frame": run["annotator_speed_up_in_reconstruction_frame"],
        }

    a, b = pick(reference), pick(other)
    return {key: round(float(b[key]) - float(a[key]), 4) for key in a}


def write_results(out: Path, results: dict[str, Any], differences_key: str) -> None:
    """Add the command and the machine to `results`, write them atomically to `out` and print the differences."""
    script = Path(sys.argv[0]).name
    results["command"] = f"python bench/{script} " + " ".join(sys.argv[1:])
    results["machine"] = {"python": platform.python_version(), "time": time.strftime("%Y-%m-%d %H:%M")}
    atomic_write_json(out, results, indent=1)
    print(json.dumps(results[differences_key], indent=1))
    print(f"wrote {out}")
