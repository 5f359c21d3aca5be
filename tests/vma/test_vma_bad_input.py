"""Bad input gives clear errors naming the file: wrong georeference, unknown classes, empty sites, foreign checkpoints."""

import json
from pathlib import Path

import numpy as np
import pytest

from models.vma.checkpoint import CheckpointError, load_checkpoint, save_version
from models.vma.config import ModelConfig, config_fingerprint
from models.vma.model import VmaNet
from models.vma.rasters import SiteInputError, load_site_rasters
from models.vma.vectors import read_vectors
from tests.vma.vma_test_sites import drawn_semantic, write_raster_site

TINY = ModelConfig(patch_px=64, num_queries=6, num_points=5, dim=32, decoder_layers=1, heads=2)


def test_georeference_that_does_not_fit_the_rasters(tmp_path: Path) -> None:
    semantic, vectors = drawn_semantic()
    geo = {"origin_xy": [0.0, 0.0], "resolution": 0.1, "width": 300, "height": 400}
    site = write_raster_site(tmp_path / "site", semantic, vectors, geo)
    with pytest.raises(SiteInputError, match=r"georeference\.json.*300 x 400.*wrong georeference"):
        load_site_rasters(site)


@pytest.mark.parametrize(
    ("geo", "message"),
    [
        ({"origin_xy": [0.0], "resolution": 0.1, "width": 600, "height": 400}, "origin_xy"),
        ({"origin_xy": [0.0, 0.0], "resolution": -0.1, "width": 600, "height": 400}, "resolution"),
        ({"origin_xy": [0.0, 0.0], "resolution": 0.1, "height": 400}, "width"),
        ({"origin_xy": [0, 0], "resolution": 0.1, "width": 600, "height": 400, "row_axis": "+y"}, "row_axis"),
    ],
)
def test_invalid_georeference_fields(tmp_path: Path, geo: dict, message: str) -> None:
    semantic, vectors = drawn_semantic()
    site = write_raster_site(tmp_path / "site", semantic, vectors, geo)
    with pytest.raises(SiteInputError, match=message):
        load_site_rasters(site)


def test_unknown_semantic_class(tmp_path: Path) -> None:
    semantic, vectors = drawn_semantic()
    semantic[5, 5] = 7
    with pytest.raises(SiteInputError, match=r"semantic\.png: unknown semantic ids \[7\]"):
        load_site_rasters(write_raster_site(tmp_path / "site", semantic, vectors))


def test_unknown_vector_class(tmp_path: Path) -> None:
    semantic, vectors = drawn_semantic()
    vectors[0]["class"] = "stop_line"
    site = write_raster_site(tmp_path / "site", semantic, vectors)
    with pytest.raises(
        ValueError, match=r"vector_map\.json: elements\[0\]\.class: unknown class 'stop_line'"
    ):
        read_vectors(site / "ground_truth" / "vector_map.json")


def test_empty_site(tmp_path: Path) -> None:
    semantic = np.zeros((100, 100), np.uint8)
    semantic[:50] = 255
    with pytest.raises(SiteInputError, match="empty site"):
        load_site_rasters(write_raster_site(tmp_path / "site", semantic, []))


def test_not_a_site(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="not a site folder"):
        load_site_rasters(tmp_path)


def test_checkpoint_from_another_config(tmp_path: Path) -> None:
    folder = save_version(tmp_path / "registry", VmaNet(TINY), {"metrics": {}})
    assert load_checkpoint(folder, TINY).config == TINY
    with pytest.raises(CheckpointError, match="another model config"):
        load_checkpoint(folder, ModelConfig())


def test_checkpoint_whose_weights_do_not_match_its_config(tmp_path: Path) -> None:
    folder = save_version(tmp_path / "registry", VmaNet(TINY), {"metrics": {}})
    meta = json.loads((folder / "checkpoint.json").read_text())
    other = {**meta["model_config"], "dim": 64, "heads": 2}
    meta.update(model_config=other, config_fingerprint=config_fingerprint(ModelConfig(**other)))
    (folder / "checkpoint.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match=r"model\.pt: weights do not fit"):
        load_checkpoint(folder)


def test_registry_without_promoted_version(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match=r"current\.json"):
        load_checkpoint(tmp_path)
