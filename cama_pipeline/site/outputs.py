"""What a per-site stage run hands back: one entry per site and the run's time, shared by the stages that
work site by site (pairs, SfM, surface) so that they report alike."""

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

SiteEntry = TypeVar("SiteEntry")


@dataclass(frozen=True)
class SiteOutputs:
    """One site's output folder and report, and whether this run skipped it as up to date."""

    site_id: str
    folder: Path
    report: dict[str, Any]
    skipped: bool


@dataclass(frozen=True)
class SitesRun(Generic[SiteEntry]):
    """What a run did, per site, and how long it took."""

    workspace: Path
    sites: tuple[SiteEntry, ...]
    seconds: float
