"""What scenes a data set holds, from its small tables only: to choose the `--scene`s of a run on a large one.

nuScenes v1.0-trainval has 850 scenes in four locations; a run works on a few of them (`cama run --scene`). This
reads scene.json, sample.json and log.json (never the large sample_data and ego_pose tables) and looks for each
scene's CAN bus files, so it answers in about a second for trainval.
"""

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.loader import find_version
from cama_pipeline.data.schema import CAN_DIR, CAN_MESSAGES, can_file_name
from cama_pipeline.data.tables import read_tables, table_path


@dataclass(frozen=True)
class SceneSummary:
    """One scene as `cama scenes` lists it."""

    name: str
    location: str
    """log.location: each city has its own map frame, and a site never joins two."""
    samples: int
    duration_s: float
    """From the scene's first to its last sample."""
    date_captured: str
    description: str
    can_bus: tuple[str, ...] = ()
    """The CAN bus messages the scene has a file of (`cama_pipeline.data.schema.CAN_MESSAGES`): nuScenes' CAN
    bus expansion leaves some scenes out, and WIGO passes the logged poses of a scene without wheel speeds
    through unfused."""

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def scene_summaries(
    root: Path, version: str | None = None, location: str | None = None
) -> list[SceneSummary]:
    """The scenes of the data set at `root` (of `location` only, when given), in scene.json's order; DatasetError
    naming the table, record and field when a scene's log or samples are missing."""
    root = Path(root)
    version_dir = root / (version or find_version(root))
    tables = read_tables(version_dir, ("scene", "sample", "log"))
    times: dict[str, list[int]] = {}
    for sample in tables["sample"].values():
        if isinstance(sample["timestamp"], int):
            times.setdefault(sample["scene_token"], []).append(sample["timestamp"])
    summaries = []
    for token, scene in tables["scene"].items():
        log = tables["log"].get(scene["log_token"])
        if log is None:
            raise DatasetError(
                f"token {scene['log_token']!r} not found in log.json",
                path=table_path(version_dir, "scene"),
                record=token,
                field="log_token",
            )
        if location is not None and log["location"] != location:
            continue
        stamps = times.get(token, [])
        summaries.append(
            SceneSummary(
                name=str(scene["name"]),
                location=str(log["location"]),
                samples=len(stamps),
                duration_s=(max(stamps) - min(stamps)) / 1e6 if stamps else 0.0,
                date_captured=str(log["date_captured"]),
                description=str(scene["description"]),
                can_bus=tuple(
                    m for m in CAN_MESSAGES if (root / CAN_DIR / can_file_name(scene["name"], m)).is_file()
                ),
            )
        )
    return summaries
