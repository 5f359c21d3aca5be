"""CAMA's `map_labels.json`: the type table, the instance model, and the JSON reading and validation helpers the
CAMA (and MapTR) readers share. One place for what an instance looks like; the layout around it is written by
`annotations.cama_release` (the public one) and read by `annotations.cama_import` (that one, a plain release, and
our older folder-per-site layout).

An instance: {"attrs": {"type"}, "data": [[u, v], ...], "id", "luid", "point_attrs", "shape_type": "polyline",
"struct_type": "parsing", "track_id"}; `data` in map pixels. CAMA's own reader uses only `attrs.type` and `data`.

Type table (one place): divider <-> lane_marking, boundary <-> Road_teeth, ped_crossing <-> Crosswalk_Line.
`Stop_Line` has no class of ours: import skips it unless `stop_line_as_divider`.
"""

import json
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, RootModel, ValidationError

from annotations.schema import ElementClass

CamaType = Literal["lane_marking", "Road_teeth", "Crosswalk_Line", "Stop_Line"]
CAMA_TYPE_FROM_CLASS: dict[ElementClass, CamaType] = {
    "divider": "lane_marking",
    "boundary": "Road_teeth",
    "ped_crossing": "Crosswalk_Line",
}
CLASS_FROM_CAMA_TYPE: dict[str, ElementClass] = {cama: ours for ours, cama in CAMA_TYPE_FROM_CLASS.items()}
MAP_LABELS = Path("maps/map_labels.json")
UV_DECIMALS = 4
"""Digits kept of a label point's pixel coordinates (1e-4 px = 10 micrometres at 0.1 m per pixel)."""
_M = TypeVar("_M", bound=BaseModel)


class CamaAttrs(BaseModel):
    """Instance attributes; the reference code reads only `type`."""

    model_config = ConfigDict(extra="allow")

    type: CamaType = Field(description="CAMA element type.")


class CamaInstance(BaseModel):
    """One instance of `map_labels.json`: a polyline in BEV-raster pixels [u = column, v = row]."""

    model_config = ConfigDict(extra="allow", allow_inf_nan=False)

    attrs: CamaAttrs
    data: list[tuple[float, float]] = Field(min_length=2, description="[u, v] BEV pixels (column, row).")
    id: str | int = Field(description="Instance id (ours: the element id).")
    luid: str | int | None = Field(default=None, description="Label unique id.")
    point_attrs: list[list[Any]] = Field(default_factory=list, description="One list per point.")
    shape_type: Literal["polyline"] = "polyline"
    struct_type: Literal["parsing"] = "parsing"
    track_id: str | int | None = None


class CamaMapLabels(RootModel[list[CamaInstance]]):
    """The whole `map_labels.json`: a list of instances."""


def format_validation_error(path: Path | str, error: ValidationError) -> str:
    """`file: [3].attrs.type: unknown type 'Foo' ...`, one line per problem, for a ValueError."""
    lines = []
    for item in error.errors():
        loc = "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in item["loc"])
        loc = loc.lstrip(".") or "(root)"
        message = item["msg"]
        if item["type"] == "literal_error" and item["loc"]:
            expected = item.get("ctx", {}).get("expected", "")
            message = f"unknown {item['loc'][-1]} {item['input']!r}; expected {expected}"
        lines.append(f"{Path(path).name}: {loc}: {message}")
    return f"{path}: invalid file\n" + "\n".join(lines) if len(lines) > 1 else lines[0]


def read_json_file(path: Path) -> Any:
    """Parse a JSON file; FileNotFoundError / ValueError naming it."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from error


def validate_file(model: type[_M], obj: Any, path: Path) -> _M:
    """Validate a parsed file against its model; ValueError naming the file and field path."""
    try:
        return model.model_validate(obj)
    except ValidationError as error:
        raise ValueError(format_validation_error(path, error)) from error


def class_from_cama_type(cama_type: str, *, stop_line_as_divider: bool = False) -> ElementClass | None:
    """Our class for a CAMA type; None for `Stop_Line` unless mapped to divider; ValueError when unknown."""
    if cama_type in CLASS_FROM_CAMA_TYPE:
        return CLASS_FROM_CAMA_TYPE[cama_type]
    if cama_type == "Stop_Line":
        return "divider" if stop_line_as_divider else None
    raise ValueError(f"type: unknown CAMA type {cama_type!r}")


def cama_instance(
    instance_id: str, cls: ElementClass, uv: np.ndarray, *, track_id: int, element_id: str | None = None
) -> dict[str, Any]:
    """One `map_labels.json` instance of our class `cls` at pixels `uv` (N, 2). `element_id` (our extension,
    ignored by CAMA's reader) names the element a piece was cut from when `instance_id` is the piece's."""
    instance: dict[str, Any] = {
        "attrs": {"type": CAMA_TYPE_FROM_CLASS[cls]},
        "data": np.round(np.asarray(uv, dtype=float), UV_DECIMALS).tolist(),
        "id": instance_id,
        "luid": instance_id,
        "point_attrs": [[] for _ in range(len(uv))],
        "shape_type": "polyline",
        "struct_type": "parsing",
        "track_id": track_id,
    }
    if element_id is not None:
        instance["element_id"] = element_id
    return instance


def validated_instances(instances: list[dict[str, Any]], where: Path) -> list[dict[str, Any]]:
    """The instances validated against the model (ValueError naming `where` and the field), as JSON objects."""
    validated = validate_file(CamaMapLabels, instances, where)
    return [item.model_dump(mode="json") for item in validated.root]
