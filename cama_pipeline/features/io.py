"""The features stage's report, `features/<site_id>/features.json` (`Workspace.features_report`): the only module
that reads or writes it. The site's COLMAP database beside it (`Workspace.features_db`) is
`cama_pipeline.features.database`'s.

    schema "cama.features/1": {"schema", "site_id", "extractor", "matcher",
        "images": {name: {"features", "masked" (null when an interrupted run extracted it)}},
        "low_feature_images": [name], "pairs_listed", "pairs_pruned", "pairs_verified", "median_inliers",
        "seconds": {"extract", "match"},
        "fingerprint": code, config, extractor, matcher, manifest and pair list,
        "database_bytes": the database's size as the stage left it (not its mtime: merely reading a SQLite
                          database can touch that)}
"""

from pathlib import Path
from typing import Any

from cama_pipeline.io import atomic_write_json, read_json

FEATURES_SCHEMA = "cama.features/1"


def write_report(path: Path, report: dict[str, Any]) -> dict[str, Any]:
    """Write features.json atomically (last: its fingerprint marks the site done); returns what was written."""
    stored = {"schema": FEATURES_SCHEMA, **report}
    atomic_write_json(path, stored, indent=1)
    return stored


def read_report(path: Path) -> dict[str, Any]:
    """A stored features.json, schema-checked; FileNotFoundError says to run `cama features`."""
    return read_json(path, FEATURES_SCHEMA, "cama features")
