"""`bench/image_resolution.py` pairs one layout built at two image sizes; anything else is refused by name."""

import json
import sys
from pathlib import Path

import pytest

from bench import image_resolution
from bench.image_resolution import PairError, checked_pair, image_size
from cama_pipeline.site_identity import SeenSiteError


def built(root: Path, name: str, layout: dict, size: tuple[int, int]) -> Path:
    site = root / name
    site.mkdir()
    config = {"layout": layout, "camera": {"width_px": size[0], "height_px": size[1]}}
    manifest = {"preset": "tiny", "seed": 9221, "config": config}
    (site / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    return site


def test_one_layout_at_two_sizes_is_a_pair(tmp_path: Path) -> None:
    low = built(tmp_path, "low", {"lanes": 2}, (256, 144))
    high = built(tmp_path, "high", {"lanes": 2}, (512, 288))
    assert image_size(high) == (512, 288)
    pair = checked_pair(low, high)
    assert pair["image_sizes"] == [(256, 144), (512, 288)]
    assert pair["sites"] == [str(low), str(high)]


def test_other_layouts_and_sizes_in_the_wrong_order_are_refused(tmp_path: Path) -> None:
    low = built(tmp_path, "low", {"lanes": 2}, (256, 144))
    other = built(tmp_path, "other", {"lanes": 3}, (512, 288))
    with pytest.raises(PairError, match="different layouts"):
        checked_pair(low, other)
    same = built(tmp_path, "same", {"lanes": 2}, (256, 144))
    with pytest.raises(PairError, match="is not rendered smaller"):
        checked_pair(low, same)
    high = built(tmp_path, "high", {"lanes": 2}, (512, 288))
    with pytest.raises(PairError, match="is not rendered smaller"):
        checked_pair(high, low)


def test_a_checkpoint_is_refused_on_a_site_it_saw(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    low = built(tmp_path, "low", {"lanes": 2}, (256, 144))
    high = built(tmp_path, "high", {"lanes": 2}, (512, 288))

    def seen(path: Path, sites: list[Path]) -> None:
        raise SeenSiteError(f"{sites[1]}: VMA checkpoint {path} was trained on this folder")

    monkeypatch.setattr(image_resolution, "unseen_mask_checkpoint", seen)
    out = tmp_path / "image_resolution.json"
    monkeypatch.setattr(sys, "argv", ["image_resolution.py", "--pair", f"{low},{high}", "--out", str(out)])
    with pytest.raises(SystemExit) as exited:
        image_resolution.main()
    assert exited.value.code == 2
    error = capsys.readouterr().err
    assert f"image_resolution: {high}" in error and "trained on" in error
    assert not out.exists()
