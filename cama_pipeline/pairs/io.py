"""The pair files of a site (`Workspace.pairs_txt`, `Workspace.pairs_json`): the only module that reads or
writes them.

    <workspace>/pairs/<site_id>/pairs.txt    one "nameA nameB" line per pair (COLMAP's imported pair list)
    <workspace>/pairs/<site_id>/pairs.json   schema "cama.pairs/1":
        {"schema", "site_id", "fingerprint", "config": {...}, "images": int,
         "counts": {"exhaustive", "temporal", "rig", "repeat", "hsp", "total"},
         "hsp_funnel": {"candidates", "dropped": {rule: n}, "kept", "repeated_views",
                        "free_height_offsets_m": {scene: metres}},
         "pairs": [[nameA, nameB, reason]]}     reason: "temporal" | "rig" | "repeat" | "hsp"
Image names are paths relative to the data set root.
"""

from dataclasses import asdict
from pathlib import Path
from typing import Any

from cama_pipeline.io import WorkspaceError, atomic_write_bytes, atomic_write_json, read_json
from cama_pipeline.pairs.config import PairsConfig

PAIRS_SCHEMA = "cama.pairs/1"
PAIR_REASONS = ("temporal", "rig", "repeat", "hsp")
"""Why a pair was chosen, in the order the counts list them."""


def write_pairs(
    txt_path: Path,
    json_path: Path,
    *,
    site_id: str,
    digest: str,
    config: PairsConfig,
    images: int,
    counts: dict[str, int],
    funnel: dict[str, Any],
    pairs: list[tuple[str, str, str]],
) -> None:
    """Write pairs.txt and then pairs.json (the JSON, carrying the fingerprint, last: it marks completion)."""
    text = "".join(f"{a} {b}\n" for a, b, _ in pairs)
    atomic_write_bytes(txt_path, text.encode("utf-8"))
    atomic_write_json(
        json_path,
        {
            "schema": PAIRS_SCHEMA,
            "site_id": site_id,
            "fingerprint": digest,
            "config": asdict(config),
            "images": images,
            "counts": counts,
            "hsp_funnel": funnel,
            "pairs": [list(p) for p in pairs],
        },
    )


def read_pairs(path: Path) -> dict[str, Any]:
    """pairs.json of a site, checked; FileNotFoundError says to run `cama pairs`."""
    data = read_json(path, PAIRS_SCHEMA, "cama pairs")
    pairs = data.get("pairs")
    if not isinstance(pairs, list) or not all(isinstance(p, list) and len(p) == 3 for p in pairs):
        raise WorkspaceError(f"{path}: field 'pairs' must be a list of [nameA, nameB, reason]")
    return data
