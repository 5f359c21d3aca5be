"""What every stage's `run` hands back: one entry per item (a scene for wigo and keyframes, a site for every
later stage) with its output, its report and whether this run skipped it as up to date; and the run's time."""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cama_pipeline.workspace import Workspace


@dataclass(frozen=True)
class ItemResult:
    """One scene's or site's outputs of a stage run."""

    name: str
    """The scene name (wigo, keyframes) or the site id (sites and later stages)."""
    path: Path
    """Its output: the scene's file (wigo, keyframes), the site's manifest (sites) or the site's folder (pairs,
    features, sfm, surface)."""
    report: dict[str, Any]
    """What the stage reported about it, as stored with its output (documented by the stage's io module)."""
    skipped: bool
    """This run found the output up to date and left it as it was."""


@dataclass(frozen=True)
class StageResult:
    """What a stage run did, item by item, and how long it took."""

    stage: str
    workspace: Workspace
    items: tuple[ItemResult, ...]
    seconds: float
    report: dict[str, Any] = field(default_factory=dict)
    """What the stage reported about the whole run, when it writes such a file (sites: `sites/index.json`)."""

    @property
    def skipped(self) -> tuple[str, ...]:
        """Names of the items this run left as they were (up to date)."""
        return tuple(item.name for item in self.items if item.skipped)

    @property
    def paths(self) -> dict[str, Path]:
        """Each item's output by name."""
        return {item.name: item.path for item in self.items}

    def item(self, name: str) -> ItemResult:
        """The entry of one scene or site; KeyError naming it and the known ones."""
        for item in self.items:
            if item.name == name:
                return item
        raise KeyError(f"{self.stage}: no item {name!r}; this run has {[i.name for i in self.items]}")
