"""`bench/rebuild_spread.py` rebuilds a site from its data alone: the data set, truth and manifest are copied, the
workspace is not, and a folder that is not a synthetic site is named."""

from pathlib import Path

import pytest

from bench.rebuild_spread import copy_site, spread


def make_site(root: Path) -> Path:
    (root / "nuscenes" / "samples").mkdir(parents=True)
    (root / "nuscenes" / "samples" / "image.jpg").write_bytes(b"jpeg")
    (root / "ground_truth").mkdir()
    (root / "ground_truth" / "vectors.json").write_text("{}")
    (root / "manifest.json").write_text('{"seed": 9013}')
    (root / "workspace" / "sfm").mkdir(parents=True)  # an earlier reconstruction, not to be reused
    return root


def test_a_rebuild_starts_from_the_data_alone(tmp_path: Path) -> None:
    copy = copy_site(make_site(tmp_path / "site"), tmp_path / "rebuild")
    assert (copy / "nuscenes" / "samples" / "image.jpg").read_bytes() == b"jpeg"
    assert (copy / "ground_truth" / "vectors.json").is_file() and (copy / "manifest.json").is_file()
    assert not (copy / "workspace").exists()
    assert spread([45.6, 56.9, 48.0]) == pytest.approx(11.3)


def test_a_folder_without_ground_truth_is_named(tmp_path: Path) -> None:
    site = make_site(tmp_path / "site")
    (site / "ground_truth" / "vectors.json").unlink()
    (site / "ground_truth").rmdir()
    with pytest.raises(ValueError, match=r"ground_truth is missing"):
        copy_site(site, tmp_path / "rebuild")
    assert not (tmp_path / "rebuild").exists()  # nothing half-copied
