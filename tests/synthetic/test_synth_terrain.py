"""`cama synth --terrain-rise/--ramp-width`: a hillier site. The ramp replaces the preset's (or the randomised
draw's), the ray marcher's grade bound follows the steeper terrain (so rays still meet an uphill road), and a ramp
steeper than a street is refused naming the width that would do."""

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from cama_pipeline.synthetic.config import STEEPEST_STREET_GRADE, TerrainConfig, preset, with_ramp
from cama_pipeline.synthetic.generate import MANIFEST
from cama_pipeline.synthetic.render import FAR_M, intersect_ground
from cama_pipeline.synthetic.terrain import Terrain
from cama_studio.cli import app

NEAR_M = 30.0
"""Range within which the marcher must find every ground hit (the surface stage observes the ground to 21 m)."""


def test_a_ramp_replaces_the_presets_and_raises_the_grade_bound_only_when_needed():
    base = preset("default").terrain
    gentle = with_ramp(base, 2.0, None)
    assert (gentle.rise_m, gentle.ramp_width_m, gentle.max_grade) == (2.0, base.ramp_width_m, base.max_grade)
    steep = with_ramp(base, -8.0, 30.0)
    assert (steep.rise_m, steep.ramp_width_m) == (-8.0, 30.0)
    assert steep.max_grade == pytest.approx(8.0 / 60.0 + base.grade_besides_ramp())
    assert steep.cross_slope == base.cross_slope and steep.wave_amplitude_m == base.wave_amplitude_m
    assert with_ramp(base, None, None) == base


def test_a_ramp_steeper_than_a_street_is_refused_naming_the_width_that_would_do():
    base = preset("default").terrain
    with pytest.raises(ValueError, match=r"rise of 20 m over a ramp width of 30 m is too steep") as refused:
        with_ramp(base, 20.0, 30.0)
    widest = int(str(refused.value).rsplit("at least ", 1)[1].split()[0])
    with_ramp(base, 20.0, widest)  # the width it names is accepted
    with pytest.raises(ValueError):
        with_ramp(base, 20.0, widest - 1)
    for rise, width in ((math.nan, 30.0), (4.0, 0.0), (4.0, -5.0), (math.inf, 30.0)):
        with pytest.raises(ValueError, match="must be finite"):
            with_ramp(base, rise, width)
    assert STEEPEST_STREET_GRADE == 0.2


def _first_hit_by_scanning(terrain: Terrain, origin: np.ndarray, direction: np.ndarray) -> float:
    """The first ray length at which the ray is below the terrain, by 1 cm steps (inf: none within FAR_M)."""
    t = torch.arange(0.01, FAR_M, 0.01, dtype=torch.float64)
    points = torch.from_numpy(origin)[None, :] + t[:, None] * torch.from_numpy(direction)[None, :]
    below = torch.nonzero(points[:, 2] <= terrain.height(points[:, 0], points[:, 1])).squeeze(1)
    return float(t[below[0]]) if len(below) else math.inf


@pytest.mark.parametrize("heading", [0.0, math.pi])
def test_rays_meet_a_steep_ramp_where_it_is_uphill_and_downhill(heading):
    terrain = Terrain(with_ramp(TerrainConfig(), 8.0, 30.0))
    world = SimpleNamespace(terrain=terrain, ground_height=terrain.height)
    origin = np.array([-10.0, 0.0, float(terrain.height(torch.tensor(-10.0), torch.tensor(0.0))) + 1.5])
    pitches = np.radians([-30.0, -10.0, -4.0, -1.0, 0.0, 2.0, 4.0])  # up to 4 degrees above the horizon
    directions = np.stack(
        [np.cos(pitches) * math.cos(heading), np.cos(pitches) * math.sin(heading), np.sin(pitches)], axis=1
    )
    lengths = intersect_ground(world, origin, torch.from_numpy(directions.astype(np.float32)))  # type: ignore[arg-type]
    scanned = [_first_hit_by_scanning(terrain, origin, d) for d in directions]
    hits = sum(math.isfinite(s) for s in scanned)
    assert hits == (7 if heading == 0.0 else 3)  # uphill, rays 4 degrees above the horizon meet the ramp too
    for length, truth in zip(lengths.tolist(), scanned, strict=True):
        if truth < NEAR_M:
            assert length == pytest.approx(truth, abs=0.05)
        else:  # grazing rays far away may be left unhit (inf: drawn as sky), never hit short
            assert math.isinf(length) or length == pytest.approx(truth, abs=0.05)


def test_cli_writes_the_ramp_into_the_manifest_and_refuses_a_cliff(tmp_path):
    out = tmp_path / "hilly"
    args = ["synth", "--preset", "tiny", "--no-images", "--terrain-rise", "5", "--ramp-width", "20"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    terrain = json.loads((out / MANIFEST).read_text())["config"]["terrain"]
    assert (terrain["rise_m"], terrain["ramp_width_m"]) == (5.0, 20.0)
    assert terrain["max_grade"] > preset("tiny").terrain.max_grade
    cliff = tmp_path / "cliff"
    result = CliRunner().invoke(
        app, ["synth", "--preset", "tiny", "--terrain-rise", "30", "--out", str(cliff)]
    )
    assert result.exit_code == 2
    assert "too steep" in result.output and "widen the ramp to at least" in result.output
    assert not cliff.exists()


def test_a_randomised_site_keeps_its_draws_but_the_ramp(tmp_path):
    out = tmp_path / "random"
    args = ["synth", "--preset", "tiny", "--random-seed", "5", "--no-images", "--terrain-rise", "-3"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    config = json.loads((out / MANIFEST).read_text())["config"]
    from cama_pipeline.synthetic.randomise import randomised_config

    drawn = randomised_config(5, base="tiny").terrain
    assert config["terrain"]["rise_m"] == -3.0
    assert config["terrain"]["ramp_width_m"] == drawn.ramp_width_m
    assert config["terrain"]["wave_length_m"] == drawn.wave_length_m
    assert config["random_seed"] == 5
