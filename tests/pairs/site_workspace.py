"""A workspace for the tiny site made by the real upstream stages (WIGO, keyframes, sites)."""

from pathlib import Path

from cama_pipeline.keyframes import KeyframeConfig
from cama_pipeline.keyframes import run as run_keyframes
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.stage import run as run_sites
from cama_pipeline.wigo import WigoConfig
from cama_pipeline.wigo import run as run_wigo


def build_site_workspace(dataset_root: Path, workspace: Path) -> Path:
    """Run wigo -> keyframes -> sites into `workspace`; returns it."""
    run_wigo(WigoConfig(), dataset_root, workspace, show_progress=False)
    run_keyframes(KeyframeConfig(), dataset_root, workspace)
    run_sites(SiteConfig(), dataset_root, workspace)
    return workspace
