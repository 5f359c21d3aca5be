"""Reading the evaluation inputs: vector maps and true poses in the ground-truth JSON formats.

Vector map (`vector_map.json` of the synthetic ground truth, or any map in the same shape):
    {"elements": [{"id": str, "class": "divider" | "ped_crossing" | "boundary",
                   "points": [[x, y, z], ...] or [[x, y], ...] (global metres), "closed": bool (optional)}]}
A 2D map (no z) is evaluated under the flat-ground assumption: each frame gives it the ego pose's height.

True poses (`poses.json`): {sample_data_token: {"rotation": [w, x, y, z], "translation": [x, y, z], ...}},
each the true `global_from_ego` at that image's capture time.
"""

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from annotations.schema import ELEMENT_CLASSES
from cama_pipeline.data import Pose

logger = logging.getLogger(__name__)


class EvaluationInputError(ValueError):
    """An evaluation input file that cannot be used; the message names the file and field."""


@dataclass(frozen=True, eq=False)
class VectorElement:
    """One map element: a polyline (or closed ring) in global metres, 2D or 3D."""

    id: str
    """Element id, unique within its map."""
    cls: str
    """One of ELEMENT_CLASSES."""
    points: np.ndarray
    """(N, 2) or (N, 3) global metres, N >= 2, finite."""
    closed: bool = False
    """True for a ring (a pedestrian-crossing outline): the last vertex joins the first."""

    def __post_init__(self) -> None:
        if self.cls not in ELEMENT_CLASSES:
            raise ValueError(
                f"element {self.id!r}: unknown class {self.cls!r}, expected one of {ELEMENT_CLASSES}"
            )
        points = np.array(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] not in (2, 3):
            raise ValueError(
                f"element {self.id!r}: points must be (N, 2) or (N, 3) with N >= 2, got {points.shape}"
            )
        if not np.isfinite(points).all():
            raise ValueError(f"element {self.id!r}: points must be finite")
        points.setflags(write=False)
        object.__setattr__(self, "points", points)

    @property
    def has_elevation(self) -> bool:
        """True when the points carry z."""
        return self.points.shape[1] == 3


def load_vector_map(path: Path) -> list[VectorElement]:
    """Read a vector map JSON file; any problem is an EvaluationInputError naming the file and field."""
    data = _read_json(path)
    elements = data.get("elements") if isinstance(data, dict) else None
    if not isinstance(elements, list):
        raise EvaluationInputError(f"{path}: field 'elements' must be a list of map elements")
    out = []
    seen: set[str] = set()
    for index, raw in enumerate(elements):
        where = f"{path}: elements[{index}]"
        if not isinstance(raw, dict):
            raise EvaluationInputError(f"{where}: must be an object")
        element_id = str(raw.get("id", f"#{index}"))
        if element_id in seen:
            raise EvaluationInputError(f"{where}.id: duplicate id {element_id!r}")
        seen.add(element_id)
        cls = raw.get("class")
        if cls not in ELEMENT_CLASSES:
            raise EvaluationInputError(
                f"{where}.class: unknown class {cls!r}, expected one of {ELEMENT_CLASSES}"
            )
        try:
            element = VectorElement(
                element_id, cls, _points(raw.get("points")), bool(raw.get("closed", False))
            )
        except (TypeError, ValueError) as err:
            raise EvaluationInputError(f"{where}.points: {err}") from None
        out.append(element)
    logger.info("read %d map elements from %s", len(out), path)
    return out


def load_true_poses(path: Path) -> dict[str, Pose]:
    """Read true `global_from_ego` poses by sample_data token; problems name the file and token."""
    data = _read_json(path)
    if not isinstance(data, dict):
        raise EvaluationInputError(f"{path}: must be an object of sample_data token -> pose")
    poses = {}
    for token, raw in data.items():
        try:
            poses[token] = Pose(np.asarray(raw["translation"], float), np.asarray(raw["rotation"], float))
        except (KeyError, TypeError, ValueError) as err:
            raise EvaluationInputError(
                f"{path}: pose {token!r}: needs 'translation' (3) and 'rotation' (4): {err}"
            ) from None
    return poses


def _points(raw: Any) -> np.ndarray:
    """A JSON list of coordinate lists as a float array (shape checked by VectorElement)."""
    if not isinstance(raw, list) or not all(isinstance(p, list) for p in raw):
        raise ValueError("must be a list of [x, y] or [x, y, z] lists")
    if any(
        not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v) for p in raw for v in p
    ):
        raise ValueError("coordinates must be finite numbers")
    if len({len(p) for p in raw}) > 1:
        raise ValueError("all points must have the same number of coordinates")
    return np.asarray(raw, dtype=np.float64)


def _read_json(path: Path) -> Any:
    """Parse a JSON file, or raise EvaluationInputError / FileNotFoundError naming it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise EvaluationInputError(f"{path}: not valid JSON: {err}") from None
