"""Night detection from metadata and, without it, from image brightness (tiny synthetic site)."""

from dataclasses import replace
from pathlib import Path

from cama_pipeline.data import load_dataset
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.night import mean_brightness, night_reason


def test_night_by_description_then_by_brightness(site_root: Path) -> None:
    dataset = load_dataset(site_root / "nuscenes", check_files=False)
    night = next(s for s in dataset.scenes if "Night" in s.description)
    day = next(s for s in dataset.scenes if "Day" in s.description)
    reason = night_reason(night, SiteConfig())
    assert reason is not None and "description" in reason
    unlabelled = replace(night, description="a drive")
    reason = night_reason(unlabelled, SiteConfig())
    assert reason is not None and "brightness" in reason
    assert night_reason(day, SiteConfig()) is None
    dark, bright = mean_brightness(unlabelled, 2), mean_brightness(day, 2)
    assert dark is not None and bright is not None and dark < 60.0 < bright


def test_unreadable_images_leave_metadata_only(site_root: Path, tmp_path: Path) -> None:
    dataset = load_dataset(site_root / "nuscenes", check_files=False)
    night = next(s for s in dataset.scenes if "Night" in s.description)
    frames = tuple(
        replace(f, images={c: replace(im, path=tmp_path / "gone.jpg") for c, im in f.images.items()})
        for f in night.frames
    )
    blind = replace(night, description="a drive", frames=frames)
    assert mean_brightness(blind, 2) is None
    assert night_reason(blind, SiteConfig()) is None
