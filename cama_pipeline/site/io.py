"""The sites stage's files, `sites/index.json` and `sites/<site_id>/manifest.json` (`Workspace.sites_index`,
`Workspace.site_manifest`): the only module that reads or writes them.

JSON, written atomically; times are int microseconds, positions global metres, quaternions [w, x, y, z],
poses global_from_ego.

    sites/index.json           schema "cama.sites/1": the aggregation's decisions
        {"schema", "fingerprint", "config": {...},
         "sites": [{"site_id", "location": log.location shared by its scenes, "scenes": [scene],
                    "merged": {stationary scene: moving scene}}],
         "dropped": [{"scene", "reason"}]}
    sites/<site_id>/manifest.json   schema "cama.site/1": everything a site's reconstruction reads
        {"schema", "site_id", "location", "scenes": [{"scene", "scene_token", "kind": "moving" | "stationary",
                                          "merged_into": scene or null,
                                          "frames": [frame as in `cama_pipeline.keyframes.io`]}],
         "poses": {sample_data token: {"scene", "channel", "timestamp_us", "translation", "rotation"}}}
"""

from pathlib import Path
from typing import Any

from cama_pipeline.io import atomic_write_json, field, read_json

SITES_SCHEMA = "cama.sites/1"
SITE_SCHEMA = "cama.site/1"


def write_sites_index(path: Path, index: dict[str, Any]) -> None:
    """Write `sites/index.json` (built by `cama_pipeline.site.stage`) atomically."""
    atomic_write_json(path, {"schema": SITES_SCHEMA, **index}, indent=1)


def read_sites_index(path: Path) -> dict[str, Any]:
    """Read `sites/index.json`; checks the schema and that `sites` and `dropped` are lists."""
    data = read_json(path, SITES_SCHEMA, "cama sites")
    field(data, "sites", list, path)
    field(data, "dropped", list, path)
    return data


def write_site_manifest(path: Path, manifest: dict[str, Any]) -> None:
    """Write one site's `manifest.json` atomically."""
    atomic_write_json(path, {"schema": SITE_SCHEMA, **manifest})


def read_site_manifest(path: Path) -> dict[str, Any]:
    """Read a site manifest; checks the schema and the `scenes` and `poses` fields."""
    data = read_json(path, SITE_SCHEMA, "cama sites")
    field(data, "scenes", list, path)
    field(data, "poses", dict, path)
    return data


def read_site_ids(path: Path) -> list[str]:
    """The site ids of `sites/index.json`, in its order (what every per-site stage runs over)."""
    return [entry["site_id"] for entry in read_sites_index(path)["sites"]]


def read_site_scenes(path: Path) -> list[str]:
    """Every scene of the sites of `sites/index.json` (a site's scenes include its merged stationary ones), once
    each, in its order: what the per-site stages load of the data set (`load_dataset(scenes=...)`)."""
    names: dict[str, None] = {}
    for entry in read_sites_index(path)["sites"]:
        names.update(dict.fromkeys(entry["scenes"]))
    return list(names)


def read_site_location(path: Path, site_id: str) -> str:
    """The `log.location` of a site of `sites/index.json`; ValueError naming the index when it has no such site."""
    for entry in read_sites_index(path)["sites"]:
        if entry["site_id"] == site_id:
            return str(entry.get("location", ""))
    raise ValueError(f"{path}: no site {site_id!r}")


def manifest_scenes(manifest: dict[str, Any]) -> list[str]:
    """The scene names of a site manifest (`read_site_manifest`), in its order."""
    return [str(entry["scene"]) for entry in manifest["scenes"]]
