"""Randomised sites: one seed, one config and one set of images; every drawn config valid and drivable; and the
look fields (appearance, camera) really change the pixels."""

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic.config import AppearanceConfig, SynthConfig, preset
from cama_pipeline.synthetic.generate import MANIFEST
from cama_pipeline.synthetic.layout import build_layout
from cama_pipeline.synthetic.randomise import randomised_config
from cama_pipeline.synthetic.render_jobs import render_shot
from cama_pipeline.synthetic.routes import plan_clips
from cama_pipeline.synthetic.site_model import SEED_ROUTES, SyntheticSite, build_synthetic_site, sub_rng
from cama_pipeline.synthetic.terrain import Terrain
from cama_studio.cli import app

SHOT = (0, 0)
"""Clip 0 (moving, day), shot 0 (CAM_FRONT of the first sweep): a view of road, paint and sky."""


def _shot(site: SyntheticSite, root: Path) -> tuple[np.ndarray, np.ndarray, bytes]:
    """Render SHOT of `site` into `root`; (RGB image, semantic mask, JPEG bytes)."""
    render_shot(site, *SHOT, root)
    jpg = next(root.rglob("*.jpg"))
    semantic = np.asarray(cv2.imread(str(next((root / "semantic").rglob("*.png"))), cv2.IMREAD_UNCHANGED))
    return np.asarray(cv2.imread(str(jpg)))[:, :, ::-1].astype(np.float32), semantic, jpg.read_bytes()


def _with_look(site: SyntheticSite, **changes: object) -> SyntheticSite:
    """The site rebuilt from its config with appearance fields changed."""
    look = dataclasses.replace(site.config.appearance, **changes)  # type: ignore[arg-type]
    return build_synthetic_site(dataclasses.replace(site.config, appearance=look))


def _with_camera(site: SyntheticSite, **changes: object) -> SyntheticSite:
    """The site rebuilt from its config with camera fields changed."""
    camera = dataclasses.replace(site.config.camera, **changes)  # type: ignore[arg-type]
    return build_synthetic_site(dataclasses.replace(site.config, camera=camera))


@pytest.fixture(scope="module")
def default_site() -> SyntheticSite:
    return build_synthetic_site(preset("tiny"))


@pytest.fixture(scope="module")
def default_shot(default_site, tmp_path_factory) -> tuple[np.ndarray, np.ndarray, bytes]:
    return _shot(default_site, tmp_path_factory.mktemp("default-shot"))


def test_same_seed_same_config_other_seed_other_config():
    assert randomised_config(5) == randomised_config(5)
    assert randomised_config(5) != randomised_config(6)
    a, b = randomised_config(5), randomised_config(6)
    for part in ("layout", "terrain", "appearance", "camera"):
        assert getattr(a, part) != getattr(b, part), part
    assert (a.location, b.location) == ("synth-random-5", "synth-random-6")
    assert a.site_origin_xy != b.site_origin_xy
    assert a.camera.width_px == preset("tiny").camera.width_px
    assert randomised_config(5, base="large").camera.width_px == preset("large").camera.width_px


def test_drawn_configs_vary_and_every_one_validates_and_is_drivable():
    configs = [randomised_config(seed) for seed in range(24)]
    for cfg in configs:
        again = SynthConfig(**{f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)})
        assert again == cfg  # __post_init__ of every part ran and accepted it
        layout = build_layout(cfg.layout)
        assert layout.road.geom_type == "Polygon"
        clips = plan_clips(cfg, layout, Terrain(cfg.terrain), sub_rng(cfg.seed, SEED_ROUTES))
        assert [c.kind for c in clips] == ["moving", "moving", "stationary", "night"]
    assert {c.layout.main_lanes_per_direction for c in configs} == {1, 2, 3}
    assert len({c.layout.dash_gap_m for c in configs}) == len(configs)
    assert {c.terrain.rise_m > 0 for c in configs} == {True, False}
    assert len({c.camera.jpeg_quality for c in configs}) > 10
    assert len({c.site_origin_xy for c in configs}) == len(configs)
    with pytest.raises(ValueError, match="random seed"):
        randomised_config(-1)


def test_same_seed_same_image_other_seed_other_image(tmp_path):
    first = _shot(build_synthetic_site(randomised_config(3)), tmp_path / "a")
    again = _shot(build_synthetic_site(randomised_config(3)), tmp_path / "b")
    other = _shot(build_synthetic_site(randomised_config(4)), tmp_path / "c")
    assert first[2] == again[2]
    assert first[2] != other[2]
    assert np.abs(first[0] - other[0]).mean() > 5.0


def _mean_on(image: np.ndarray, semantic: np.ndarray, cls: Semantic) -> float:
    return float(image[semantic == int(cls)].mean())


def test_surface_colours_sky_sun_and_exposure_change_their_pixels(default_site, default_shot, tmp_path):
    image, semantic, _ = default_shot
    darker_road = _shot(_with_look(default_site, asphalt_rgb=(0.15, 0.15, 0.16)), tmp_path / "asphalt")[0]
    assert _mean_on(darker_road, semantic, Semantic.ROAD) < _mean_on(image, semantic, Semantic.ROAD) - 20
    red_sky = _shot(
        _with_look(default_site, sky_zenith_rgb=(0.8, 0.2, 0.2), sky_horizon_rgb=(0.8, 0.3, 0.3)),
        tmp_path / "sky",
    )[0]
    sky = semantic == int(Semantic.SKY)
    assert red_sky[sky][:, 0].mean() > image[sky][:, 0].mean() + 40
    low_sun = _shot(_with_look(default_site, sun_direction=(0.0, -0.97, 0.243)), tmp_path / "sun")[0]
    assert _mean_on(low_sun, semantic, Semantic.ROAD) < _mean_on(image, semantic, Semantic.ROAD) - 5
    bright = _shot(_with_look(default_site, exposure_gain=1.5), tmp_path / "exposure")[0]
    assert _mean_on(bright, semantic, Semantic.ROAD) > 1.3 * _mean_on(image, semantic, Semantic.ROAD)


def test_texture_contrast_and_paint_wear_change_their_pixels(default_site, default_shot, tmp_path):
    image, semantic, _ = default_shot
    road = semantic == int(Semantic.ROAD)
    flat = _shot(_with_look(default_site, texture_contrast=0.0), tmp_path / "flat")[0]
    rough = _shot(_with_look(default_site, texture_contrast=2.5), tmp_path / "rough")[0]
    assert flat[road].std() < image[road].std() < rough[road].std()
    paint = np.isin(semantic, [int(Semantic.LANE_MARKING), int(Semantic.CROSSWALK)])
    assert paint.sum() > 200
    faded = _shot(_with_look(default_site, paint_fade=0.8), tmp_path / "faded")
    missing = _shot(_with_look(default_site, paint_missing=0.6), tmp_path / "missing")
    assert faded[0][paint].mean() < image[paint].mean() - 30
    assert missing[0][paint].mean() < image[paint].mean() - 20
    assert np.array_equal(faded[1], semantic) and np.array_equal(missing[1], semantic)  # labels stay whole
    near_paint = cv2.dilate(paint.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0  # anti-aliased paint edges
    away = np.abs(missing[0][~near_paint] - image[~near_paint])
    assert away.mean() < 0.5 and np.percentile(away, 99) <= 3  # only the paint changed (JPEG ringing aside)


def test_camera_blur_noise_and_jpeg_quality_change_the_images(default_site, default_shot, tmp_path):
    image, _, jpeg = default_shot

    def sharpness(rgb: np.ndarray) -> float:
        return float(cv2.Laplacian(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), cv2.CV_32F).var())

    blurred = _shot(_with_camera(default_site, blur_sigma_px=1.5), tmp_path / "blur")[0]
    noisy = _shot(_with_camera(default_site, noise_sigma=0.05), tmp_path / "noise")[0]
    assert sharpness(blurred) < 0.5 * sharpness(image)
    assert sharpness(noisy) > 2.0 * sharpness(image)
    coarse = _shot(_with_camera(default_site, jpeg_quality=40), tmp_path / "jpeg")[2]
    assert len(coarse) < 0.7 * len(jpeg)


def test_bad_look_fields_are_refused_naming_them():
    with pytest.raises(ValueError, match="paint_missing"):
        AppearanceConfig(paint_missing=1.0)
    with pytest.raises(ValueError, match="asphalt_rgb"):
        AppearanceConfig(asphalt_rgb=(0.2, 0.2, 1.5))
    with pytest.raises(ValueError, match="sun_direction"):
        AppearanceConfig(sun_direction=(1.0, 0.0, 0.0))


@pytest.mark.slow
def test_cli_random_seed_writes_the_drawn_config_and_location(tmp_path):
    out = tmp_path / "random"
    runner = CliRunner()
    result = runner.invoke(
        app, ["synth", "--preset", "tiny", "--random-seed", "9", "--no-images", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "synth-random-9" in result.output
    manifest = json.loads((out / MANIFEST).read_text())
    expected = randomised_config(9)
    assert manifest["random_seed"] == 9 and manifest["location"] == "synth-random-9"
    assert manifest["config"] == json.loads(json.dumps(dataclasses.asdict(expected)))
    logs = json.loads((out / "nuscenes" / "v1.0-synth" / "log.json").read_text())
    assert {log["location"] for log in logs} == {"synth-random-9"}
    both = runner.invoke(app, ["synth", "--random-seed", "9", "--seed", "1", "--out", str(tmp_path / "x")])
    assert both.exit_code == 2
    assert "--random-seed" in both.output
