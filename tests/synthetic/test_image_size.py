"""`cama synth --image-size WxH`: the camera size parsed and checked (a clear error for bad text), the
intrinsics scaled with it, images and masks rendered at it. Only small sizes here: 1600x900 renders slowly."""

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.synthetic.config import CameraConfig, parse_image_size
from cama_pipeline.synthetic.generate import MANIFEST
from cama_pipeline.synthetic.render_jobs import render_shot
from cama_pipeline.synthetic.rig import NUSCENES_WIDTH_PX
from cama_pipeline.synthetic.site_model import build_synthetic_site
from cama_studio.cli import app
from tests.synthetic.synth_helpers import micro_config


def test_sizes_parse_and_bad_text_is_named():
    assert parse_image_size("1600x900") == (1600, 900)
    assert parse_image_size(" 320X180 ") == (320, 180)
    for text in ("1600", "1600x", "wide x high", "-64x36", "1600x900x3", "16.5x9"):
        with pytest.raises(ValueError, match="not WIDTHxHEIGHT"):
            parse_image_size(text)
    with pytest.raises(ValueError, match="out of range"):
        parse_image_size("32x18")
    with pytest.raises(ValueError, match="out of range"):
        parse_image_size("8000x4500")


def test_images_and_masks_render_at_the_size_with_scaled_intrinsics(tmp_path):
    cfg = micro_config()
    site = build_synthetic_site(replace(cfg, camera=replace(cfg.camera, width_px=160, height_px=90)))
    render_shot(site, 0, 0, tmp_path)
    (jpg,) = tmp_path.rglob("*.jpg")
    assert np.asarray(cv2.imread(str(jpg))).shape == (90, 160, 3)
    masks = [np.asarray(cv2.imread(str(p), cv2.IMREAD_UNCHANGED)) for p in tmp_path.rglob("*.png")]
    assert len(masks) == 2 and all(mask.shape == (90, 160) for mask in masks)
    default = {cam.channel: cam.K for cam in build_synthetic_site(cfg).rig}
    for cam in site.rig:
        assert cam.K[0, 0] == pytest.approx(default[cam.channel][0, 0] * 160 / cfg.camera.width_px)
    front = next(cam for cam in site.rig if cam.channel == "CAM_FRONT")
    assert front.K[0, 0] == pytest.approx(1266.4 * 160 / NUSCENES_WIDTH_PX)  # nuScenes' focal length, scaled


def test_cli_refuses_a_bad_size_before_writing_anything(tmp_path):
    out = tmp_path / "site"
    result = CliRunner().invoke(
        app, ["synth", "--preset", "tiny", "--image-size", "1600by900", "--out", str(out)]
    )
    assert result.exit_code == 2
    assert "'1600by900' is not WIDTHxHEIGHT" in result.output
    assert not out.exists()
    assert CameraConfig().width_px == 512  # the default site keeps its size


@pytest.mark.slow
def test_cli_image_size_reaches_the_tables_and_the_manifest(tmp_path):
    out = tmp_path / "site"
    result = CliRunner().invoke(
        app, ["synth", "--preset", "tiny", "--image-size", "320x180", "--no-images", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    camera = json.loads((out / MANIFEST).read_text())["config"]["camera"]
    assert (camera["width_px"], camera["height_px"]) == (320, 180)
    records = json.loads((out / "nuscenes" / "v1.0-synth" / "sample_data.json").read_text())
    assert {(r["width"], r["height"]) for r in records} == {(320, 180)}
    calibrations = json.loads((out / "nuscenes" / "v1.0-synth" / "calibrated_sensor.json").read_text())
    assert all(c["camera_intrinsic"][0][2] < 320 for c in calibrations)
