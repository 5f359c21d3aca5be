"""Class maps: how the label ids of another network's masks become the project's semantic ids
(`cama_pipeline.semantics`), for `cama import-masks`.

Built in (`cama_pipeline/segment/class_maps/<name>.json`, written from the published label lists, names and ids
as published):

    cityscapes            Cityscapes labelIds 0-33 (as in gtFine `*_labelIds.png`)
    cityscapes-trainids   Cityscapes trainIds 0-18 and 255 (the ignored classes), what most networks output
    mapillary-vistas      Mapillary Vistas v1.2, 66 classes (ids 0-65)
    mapillary-vistas-v2   Mapillary Vistas v2.0, 124 classes (ids 0-123)
    cama                  the project's own ids 0-8 (masks already in them, e.g. the generator's in ground_truth/)

A class map file (`--class-map FILE.json`) has the same form:

    {
      "schema": "cama.class_map/1",
      "name": "my-network",                        # shown in reports and the masks' manifest
      "label_set": "what the ids are (optional)",
      "classes": [
        {"id": 0, "name": "road", "to": "road"},   # id: the value in the mask PNG (0-65535);
        {"id": 1, "name": "sidewalk", "to": "background"},   # name: the label's own name (for messages);
        ...                                        # to: background, road, curb, lane_marking, crosswalk,
      ]                                            #     vehicle, static_object, sky or ego
    }

Every id a mask holds must be listed: an unlisted id is an error naming the id and the file, never a silent
guess. Mapping choices of the built-in maps: drivable surfaces (road, parking, bike and service lanes, manholes,
potholes) are road; sidewalks, terrain and water are background (ground that is not road); people, riders and
animals are vehicle, the project's one class of things that move (features ignore them, the surface does not take
them for ground); Mapillary's curb cut is curb, its car mount and ego vehicle are ego. Paint that is not a lane
divider or crosswalk (v2.0's arrows, symbols, text, stop and give-way lines, hatching) is road, so that the lane
instances hold dividers only; v1.2's single "Lane Marking - General" cannot be split and is lane_marking.
Cityscapes has no lane marking, crosswalk or curb class: its masks give no lane instances.
"""

import hashlib
import importlib.resources
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.semantics import Semantic

CLASS_MAP_SCHEMA = "cama.class_map/1"
BUILTIN_CLASS_MAPS: tuple[str, ...] = (
    "cityscapes",
    "cityscapes-trainids",
    "mapillary-vistas",
    "mapillary-vistas-v2",
    "cama",
)
TARGETS: dict[str, Semantic] = {m.name.lower(): m for m in Semantic if m is not Semantic.UNOBSERVED}
"""The project classes a label may map to, by the name a class map uses."""
MAX_LABEL_ID = 65535
"""Mask PNGs are 8- or 16-bit single channel."""
_UNKNOWN = 0xFFFF
"""Marks an unlisted id in the lookup table."""


class ClassMapError(ValueError):
    """A class map that cannot be read or breaks the format, or a mask holding an id the map does not list;
    the message names the file."""


@dataclass(frozen=True, eq=False)
class ClassMap:
    """Label id -> project class, with the labels' own names."""

    name: str
    label_set: str
    names: dict[int, str]
    """Label id -> its name in the source label set."""
    targets: dict[int, Semantic]
    """Label id -> project class."""
    source: str
    """Where it was read from: `built-in` or the file's path."""

    def digest(self) -> str:
        """A short hash of the mapping (what imported masks were made with; a changed map reimports)."""
        pairs = sorted((label, int(target)) for label, target in self.targets.items())
        return hashlib.sha256(json.dumps([self.name, pairs]).encode()).hexdigest()[:16]

    def table(self) -> np.ndarray:
        """(65536,) uint16 lookup: project class of each label id, `_UNKNOWN` where the map lists none."""
        table = np.full(MAX_LABEL_ID + 1, _UNKNOWN, np.uint16)
        for label, target in self.targets.items():
            table[label] = int(target)
        return table

    def apply(self, labels: np.ndarray, path: Path, table: np.ndarray | None = None) -> np.ndarray:
        """(H, W) uint8 project ids of a mask's label ids; ClassMapError naming `path` and the first unlisted ids.
        `table`: `self.table()`, passed in when many masks are mapped."""
        table = self.table() if table is None else table
        mapped = table[labels.astype(np.int64)]
        unknown = mapped == _UNKNOWN
        if unknown.any():
            ids = np.unique(labels[unknown])
            shown = ", ".join(str(int(i)) for i in ids[:5]) + (", ..." if len(ids) > 5 else "")
            raise ClassMapError(
                f"{path}: label id(s) {shown} not in class map {self.name!r} ({self.source}); "
                f"{int(unknown.sum())} pixel(s)"
            )
        return mapped.astype(np.uint8)


def load_class_map(choice: str | Path) -> ClassMap:
    """A built-in class map by name (`BUILTIN_CLASS_MAPS`) or a class map file; ClassMapError naming the file."""
    if isinstance(choice, str) and choice in BUILTIN_CLASS_MAPS:
        resource = importlib.resources.files("cama_pipeline.segment").joinpath(f"class_maps/{choice}.json")
        return parse_class_map(json.loads(resource.read_text(encoding="utf-8")), "built-in")
    path = Path(choice)
    if path.suffix.lower() != ".json" and not path.exists():
        raise ClassMapError(
            f"--class-map: {choice!r} is neither a built-in class map ({', '.join(BUILTIN_CLASS_MAPS)}) "
            "nor a .json file"
        )
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ClassMapError(f"{path}: cannot read the class map: {err.strerror or err}") from None
    except ValueError as err:
        raise ClassMapError(f"{path}: not valid JSON: {err}") from None
    return parse_class_map(data, str(path))


def parse_class_map(data: Any, source: str) -> ClassMap:
    """A ClassMap from a parsed class map file (see the module docstring); ClassMapError naming `source` and
    the entry at fault."""
    if not isinstance(data, dict) or data.get("schema") != CLASS_MAP_SCHEMA:
        raise ClassMapError(
            f"{source}: not a class map (expected an object with schema {CLASS_MAP_SCHEMA!r})"
        )
    name, classes = data.get("name"), data.get("classes")
    if not isinstance(name, str) or not name:
        raise ClassMapError(f"{source}: field 'name' must be a non-empty string")
    if not isinstance(classes, list) or not classes:
        raise ClassMapError(f"{source}: field 'classes' must be a non-empty list")
    names: dict[int, str] = {}
    targets: dict[int, Semantic] = {}
    for index, entry in enumerate(classes):
        where = f"{source}: classes[{index}]"
        if not isinstance(entry, dict):
            raise ClassMapError(f"{where} must be an object with id, name and to")
        label, label_name, target = entry.get("id"), entry.get("name", ""), entry.get("to")
        if isinstance(label, bool) or not isinstance(label, int) or not 0 <= label <= MAX_LABEL_ID:
            raise ClassMapError(f"{where}: 'id' must be an integer 0-{MAX_LABEL_ID}, got {label!r}")
        if label in targets:
            raise ClassMapError(f"{where}: id {label} listed twice")
        if target not in TARGETS:
            raise ClassMapError(f"{where}: 'to' must be one of {', '.join(TARGETS)}, got {target!r}")
        names[label] = str(label_name)
        targets[label] = TARGETS[target]
    label_set = data.get("label_set", "")
    return ClassMap(name, str(label_set), names, targets, source)
