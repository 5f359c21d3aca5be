"""The element-mask proposer: targets on the right cells, masks traced into vectors scored by probability, versions
that record and refuse their training sites, and a network that learns what the rules cannot read."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from shapely.geometry import LineString

from cama_pipeline.evaluate.observed import ObservedMask
from cama_pipeline.semantics import Semantic
from cama_pipeline.site_identity import SeenSiteError
from models.vma.checkpoint import (
    CheckpointError,
    ensure_unseen,
    load_checkpoint,
    round_to_stored,
    save_version,
)
from models.vma.element_masks.checkpoint import KIND, load_mask_checkpoint
from models.vma.element_masks.config import MaskModelConfig, MaskTrainConfig
from models.vma.element_masks.line_ends import carried_to_border, straightened_ends
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import (
    MaskInferenceConfig,
    predict_probabilities,
    read_crossing,
    refined_line,
    ring_cells,
    road_edge_band,
    road_side,
    traced_semantic,
    vectors_from_probabilities,
)
from models.vma.element_masks.targets import element_masks
from models.vma.element_masks.train import jitter_appearance, smeared_kerbs, train_masks, training_site
from models.vma.patches import site_grid
from models.vma.rasters import NUM_SEMANTIC, SiteRasters, load_site_rasters
from models.vma.rule_based import RuleConfig
from models.vma.vectors import CLASSES, Vector
from tests.vma.vma_test_sites import ORIGIN_XY, global_xy

CONFIG = MaskModelConfig()


def test_targets_draw_each_class_on_its_own_cells(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    grid = site_grid(rasters, CONFIG)
    assert grid.shape == (200, 300)  # 40 m x 60 m at 0.2 m
    line = Vector("divider", np.array([global_xy(10, 20), global_xy(50, 20)]))
    ring = Vector(
        "ped_crossing",
        np.array(
            [global_xy(30, 13), global_xy(34, 13), global_xy(34, 27), global_xy(30, 27), global_xy(30, 13)]
        ),
    )
    masks = element_masks([line, ring], grid, CONFIG)
    divider, crossing, boundary = (masks[CLASSES.index(c)] for c in ("divider", "ped_crossing", "boundary"))
    assert not boundary.any()
    rows = np.nonzero(divider[:, 100])[0]  # x = 20 m
    # the band is 0.6 m (3 cells) wide around y = 20 m: grid row (20 m - 0.05 m + 0.1 m) / 0.2 m ~ 100
    assert len(rows) == 3 and abs(rows.mean() - 99.75) <= 0.5
    assert not divider[:, 40].any()  # x = 8 m: before the line starts
    assert crossing[100, 160] == 1 and crossing[100, 145] == 0  # x = 32 m inside, x = 29 m outside
    assert grid.image.shape[0] == CONFIG.in_channels


def test_network_predicts_a_mask_per_class_and_names_a_bad_input_size() -> None:
    net = ElementMaskNet(CONFIG).eval()
    with torch.no_grad():
        out = net(torch.zeros(1, CONFIG.in_channels, 64, 96))
    assert out.shape == (1, len(CLASSES), 64, 96)
    with pytest.raises(ValueError, match="multiples of 8"):
        net(torch.zeros(1, CONFIG.in_channels, 60, 96))


def test_masks_are_traced_into_vectors_scored_by_their_probability(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    probabilities = np.zeros((len(CLASSES), *rasters.shape), np.float32)
    row = round(20 / rasters.resolution_m)
    probabilities[CLASSES.index("divider"), row - 2 : row + 3, 20:500] = 0.8  # x 2..50 m at y = 20 m
    probabilities[CLASSES.index("boundary"), round(12 / 0.1) - 2 : round(12 / 0.1) + 3, :] = 0.9
    probabilities[CLASSES.index("ped_crossing"), 130:270, 300:340] = 0.7
    semantic = traced_semantic(rasters, probabilities, 0.5)
    # the input's own marking labels are not traced: only the masks are
    assert (semantic == int(Semantic.LANE_MARKING)).sum() == 5 * 480
    vectors = vectors_from_probabilities(rasters, probabilities, MaskInferenceConfig())
    by_class = {c: [v for v in vectors if v.cls == c] for c in CLASSES}
    assert (
        len(by_class["divider"]) == 1
        and len(by_class["boundary"]) == 1
        and len(by_class["ped_crossing"]) == 1
    )
    divider = by_class["divider"][0]
    xs = sorted(divider.points[:, 0] - ORIGIN_XY[0])
    assert xs[0] < 3.0 and xs[-1] > 49.0 and np.allclose(divider.points[:, 1], ORIGIN_XY[1] - 20, atol=0.15)
    assert divider.score == pytest.approx(0.8, abs=0.05)
    assert by_class["boundary"][0].score == pytest.approx(0.9, abs=0.05)
    # the block is carried across the road to its kerbs (as the rules carry stripes), over a few empty cells
    assert 0.55 < by_class["ped_crossing"][0].score <= 0.7
    with pytest.raises(ValueError, match="boundary_source"):
        MaskInferenceConfig(rule=RuleConfig(boundary_source="road_edge"))


def test_smeared_kerbs_spread_and_break_the_kerb_label_only(rng: np.random.Generator) -> None:
    semantic = np.zeros((200, 200), np.uint8)
    semantic[:, :100] = int(Semantic.ROAD)
    semantic[:, 100:102] = int(Semantic.CURB)
    semantic[:, 150] = int(Semantic.LANE_MARKING)
    out = smeared_kerbs(semantic, 0.1, rng)
    changed = out != semantic
    assert changed.any()
    assert set(np.unique(out[changed]).tolist()) <= {int(Semantic.CURB), int(Semantic.BACKGROUND)}
    assert (out[:, :100] == int(Semantic.ROAD)).all() and (out[:, 150] == int(Semantic.LANE_MARKING)).all()


def test_appearance_jitter_recolours_seen_cells_only_and_keeps_paint_brighter(
    rng: np.random.Generator,
) -> None:
    image = np.zeros((NUM_SEMANTIC + 3, 16, 16), np.float32)
    image[int(Semantic.ROAD), :, :8] = 1.0
    image[NUM_SEMANTIC:, :, :8] = 0.3
    image[NUM_SEMANTIC:, :, 4] = 0.8  # a painted line on the road
    semantic_before = image[:NUM_SEMANTIC].copy()
    looks = []
    for _ in range(20):
        jittered = image.copy()
        jitter_appearance(jittered, rng)
        rgb = jittered[NUM_SEMANTIC:]
        assert np.array_equal(jittered[:NUM_SEMANTIC], semantic_before)
        assert (rgb[:, :, 8:] == 0).all() and rgb.min() >= 0 and rgb.max() <= 1
        assert rgb[:, :, 4].mean() >= rgb[:, :, 0].mean()
        looks.append(float(rgb[:, :, 0].mean()))
    assert max(looks) - min(looks) > 0.2, "exposures should vary widely from crop to crop"
    with pytest.raises(ValueError, match="appearance_share"):
        MaskTrainConfig(appearance_share=1.5)
    with pytest.raises(ValueError, match="threads"):
        MaskTrainConfig(threads=0)


def test_a_trained_version_records_its_sites_and_is_refused_on_them(
    bev_sites: dict[str, Path], tmp_path: Path
) -> None:
    registry = tmp_path / "registry"
    config = MaskModelConfig(base_channels=4)
    folder = train_masks(
        config,
        MaskTrainConfig(steps=2, batch_size=2, crop_px=64, damaged_copies=1, threads=1),
        [bev_sites["train"]],
        registry,
        show_progress=False,
    )
    meta = json.loads((folder / "checkpoint.json").read_text())
    assert meta["kind"] == KIND and meta["data"]["seen_sites"][0]["seed"] == 3001
    loaded = load_mask_checkpoint(registry)
    assert loaded.path == folder and loaded.model.config == config
    with pytest.raises(SeenSiteError, match="3001|trained on"):
        ensure_unseen(loaded, bev_sites["train"])
    assert ensure_unseen(loaded, bev_sites["val"]) is not None
    with pytest.raises(SeenSiteError):
        train_masks(
            config,
            MaskTrainConfig(steps=1, batch_size=1, crop_px=64, damaged_copies=0, threads=1),
            [bev_sites["train"]],
            registry,
            validation_sites=[bev_sites["train"]],
            show_progress=False,
        )
    with pytest.raises(CheckpointError, match="kind"):
        load_mask_checkpoint(Path("models/vma/checkpoints"))
    with pytest.raises(CheckpointError, match="checkpoint.json"):
        load_checkpoint(folder)
    probabilities = predict_probabilities(
        loaded.model, load_site_rasters(bev_sites["val"]), MaskInferenceConfig(tile_px=128, overlap_px=32)
    )
    assert probabilities.shape[1:] == load_site_rasters(bev_sites["val"]).shape
    assert ((probabilities >= 0) & (probabilities <= 1)).all()


def _band_site(drawn_site: Path) -> tuple:
    """The drawn site's rasters and a divider probability band whose centre wobbles 0.3 m around y = 20 m."""
    rasters = load_site_rasters(drawn_site)
    probability = np.zeros(rasters.shape, np.float32)
    for col in range(rasters.shape[1]):
        centre_y = 20.0 + 0.3 * np.sin(col * rasters.resolution_m * 2 * np.pi / 9.0)
        rows = np.arange(rasters.shape[0]) * rasters.resolution_m
        probability[:, col] = np.clip(1.0 - np.abs(rows - centre_y) / 0.4, 0.0, 1.0)
    return rasters, probability


def test_refined_lines_follow_the_band_centre_and_the_paint_where_read(drawn_site: Path) -> None:
    rasters, probability = _band_site(drawn_site)
    traced = np.array([global_xy(5, 20.15), global_xy(25, 20.15)])  # a skeleton a cell and a half off
    config = MaskInferenceConfig()
    band = refined_line(rasters, probability, traced, config)
    xs = band[:, 0] - ORIGIN_XY[0]
    expected = 20.0 + 0.3 * np.sin(xs * 2 * np.pi / 9.0)
    # on the band's centre (within the smoothing of a 9 m wave), not where the skeleton was
    assert np.abs((ORIGIN_XY[1] - band[:, 1]) - expected).max() < 0.1
    paint = (rasters.semantic == int(Semantic.LANE_MARKING)).astype(
        np.float32
    )  # dashes at y = 20 m, x 1-4, 10-13, ...
    snapped = refined_line(rasters, probability, traced, config, paint, bridge_m=7.0)
    # read paint wins, and the 6 m gaps between dashes are bridged straight instead of following the wobble;
    # before the first dash read and after the last the network's course is kept
    xs = snapped[:, 0] - ORIGIN_XY[0]
    between = (xs >= 10.0) & (xs <= 22.0)
    assert between.sum() >= 2 and np.abs((ORIGIN_XY[1] - snapped[between, 1]) - 20.0).max() < 0.06
    wave = 20.0 + 0.3 * np.sin(xs[~between] * 2 * np.pi / 9.0)
    assert np.abs((ORIGIN_XY[1] - snapped[~between, 1]) - wave).max() < 0.1
    assert refined_line(rasters, probability, traced, MaskInferenceConfig(refine_reach_m=0.0)) is traced


def test_crossings_take_the_block_of_the_stripes_read_inside_them(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    soft = np.array([global_xy(29.6, 13), global_xy(34.5, 13), global_xy(34.5, 27.2), global_xy(29.6, 27.2)])
    ring = np.vstack([soft, soft[:1]])
    read = read_crossing(rasters, ring, ring_cells(rasters, ring) > 0, MaskInferenceConfig())
    xs = read[:, 0] - ORIGIN_XY[0]
    assert xs.min() == pytest.approx(30.0, abs=0.15) and xs.max() == pytest.approx(34.0, abs=0.15)
    elsewhere = ring + np.array([15.0, 0.0])  # no stripes were read there: the network's ring stays
    inside = ring_cells(rasters, elsewhere) > 0
    assert read_crossing(rasters, elsewhere, inside, MaskInferenceConfig()) is elsewhere


def test_the_road_edge_band_straddles_the_edge_and_configs_name_bad_evidence(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    semantic = np.full(rasters.shape, int(Semantic.BACKGROUND), np.uint8)
    semantic[:, :300] = int(Semantic.ROAD)  # road west of x = 30 m, observed ground east of it
    semantic[:, 450:] = int(Semantic.UNOBSERVED)
    band = road_edge_band(replace(rasters, semantic=semantic), RuleConfig())
    assert set(np.nonzero(band.any(axis=0))[0].tolist()) == {299, 300}  # the cells on both sides of the edge
    with pytest.raises(ValueError, match="boundary_evidence"):
        MaskInferenceConfig(boundary_evidence="curb")  # type: ignore[arg-type]


def _kerb_with_hidden_face(drawn_site: Path, hidden_cells: int) -> SiteRasters:
    """Road west of x = 30 m, then `hidden_cells` unobserved columns (a kerb's face no camera saw), then observed
    ground, and unobserved again from x = 45 m."""
    rasters = load_site_rasters(drawn_site)
    semantic = np.full(rasters.shape, int(Semantic.BACKGROUND), np.uint8)
    semantic[:, :300] = int(Semantic.ROAD)
    semantic[:, 300 : 300 + hidden_cells] = int(Semantic.UNOBSERVED)
    semantic[:, 450:] = int(Semantic.UNOBSERVED)
    return replace(rasters, semantic=semantic)


def test_the_road_edge_band_spans_the_kerbs_hidden_face_and_boundaries_lie_in_its_middle(
    drawn_site: Path,
) -> None:
    rasters = _kerb_with_hidden_face(drawn_site, 3)  # unobserved x = 30.0-30.2 m: the kerb lies at 30.1 m
    across = road_edge_band(rasters, RuleConfig(), across_gap=True)
    columns = set(np.nonzero(across.any(axis=0))[0].tolist())
    assert columns == {299, 300, 301, 302, 303}  # last road cell, the strip, first ground cell
    at_edge = road_edge_band(rasters, RuleConfig())  # the product's band
    assert set(np.nonzero(at_edge.any(axis=0))[0].tolist()) == {299, 300}
    # the network's band at the road's edge (x = 29.95 m); its refined line moves to the strip's middle
    xs = np.arange(rasters.shape[1]) * rasters.resolution_m
    probability = np.tile(np.clip(1.0 - np.abs(xs - 29.95) / 0.4, 0.0, 1.0), (rasters.shape[0], 1))
    traced = np.array([global_xy(29.9, 5), global_xy(29.9, 35)])
    config = MaskInferenceConfig()
    for band, kerb_x in ((across, 30.1), (at_edge, 29.95)):
        line = refined_line(rasters, probability.astype(np.float32), traced, config, band)
        assert np.abs(line[:, 0] - ORIGIN_XY[0] - kerb_x).max() < 0.03
    # ground 2 m beyond the road is no kerb: the road runs into unseen cells there, and no band is drawn
    wide = _kerb_with_hidden_face(drawn_site, 20)
    assert not road_edge_band(wide, RuleConfig(), across_gap=True).any()


def test_a_boundary_end_pulled_aside_goes_back_on_the_lines_course() -> None:
    line = np.column_stack([np.arange(0.0, 12.5, 1.0), np.zeros(13)])
    bent = line.copy()
    bent[0] = [0.0, 0.6]  # the first vertex pulled 0.6 m aside
    bent[-1] = [12.0, -0.1]  # the last one only 0.1 m: within the tolerance
    out = straightened_ends(bent, 2.0, 0.15)
    np.testing.assert_allclose(out[0], [0.0, 0.0], atol=1e-9)  # back on the course, at its distance along it
    np.testing.assert_array_equal(out[1:], bent[1:])
    np.testing.assert_array_equal(bent[0], [0.0, 0.6])  # the input is left as it was
    bent[-1] = [12.0, -0.7]
    np.testing.assert_allclose(straightened_ends(bent, 2.0, 0.15)[-1], [12.0, 0.0], atol=1e-9)
    np.testing.assert_array_equal(straightened_ends(bent, 0.0, 0.15), bent)  # 0: never
    np.testing.assert_array_equal(
        straightened_ends(bent[:5], 2.0, 0.15), bent[:5]
    )  # too short to have a course
    curve = (
        np.column_stack([np.cos(np.linspace(0, np.pi / 2, 40)), np.sin(np.linspace(0, np.pi / 2, 40))]) * 10
    )
    np.testing.assert_allclose(straightened_ends(curve, 2.0, 0.15), curve)  # a bend follows its course
    with pytest.raises(ValueError, match="end_course_m"):
        MaskInferenceConfig(end_tolerance_m=-0.1)


def test_a_line_stopping_short_of_the_observed_edge_is_carried_on_to_it() -> None:
    observed = np.zeros((100, 200), bool)  # 0.1 m cells, origin (0, 10): x 0..20 m, y 0..10 m
    observed[:, 20:150] = True  # seen from x = 2.0 to x = 14.9
    mask = ObservedMask(observed, (0.0, 10.0), 0.1)
    line = np.column_stack([np.arange(4.0, 14.0, 1.0), np.full(10, 5.0)])  # x 4..13, 1.9 m short of the edge
    out = carried_to_border(line, mask, 2.0, 2.0, 0.4)
    np.testing.assert_array_equal(out[:-1], line)  # the start: the edge is 2.05 m behind it, beyond reach
    assert out[-1, 0] == pytest.approx(14.9, abs=0.051) and out[-1, 1] == pytest.approx(5.0)
    assert mask.contains(out[-1:]).all()  # on the last observed cell, not beyond
    assert len(carried_to_border(line, mask, 2.0, 1.5, 0.4)) == len(line)  # the edge beyond the reach: left
    near = line[line[:, 0] <= 12.0] + [2.5, 0.0]  # ends at x = 14.5, 0.4 m short, and starts at 6.5
    assert len(carried_to_border(near, mask, 2.0, 2.0, 0.5)) == len(near)  # nearer than the minimum: left
    both = carried_to_border(near - [2.5 + 0.6, 0.0], mask, 2.0, 2.0, 0.4)  # x 3.4..8.4, 1.4 m past the start
    assert both[0, 0] == pytest.approx(2.0, abs=0.051) and len(both) == len(near) + 1
    slanted = np.array([[9.0, 1.0], [12.0, 4.0], [13.0, 5.0]])  # heading +x +y at 45 degrees
    end = carried_to_border(slanted, mask, 2.0, 3.0, 0.4)[-1]
    assert end[0] - 13.0 == pytest.approx(end[1] - 5.0) and end[0] == pytest.approx(14.9, abs=0.051)
    np.testing.assert_array_equal(carried_to_border(line, mask, 2.0, 0.0, 0.0), line)  # 0: never
    with pytest.raises(ValueError, match="border_min_m"):
        MaskInferenceConfig(border_reach_m=0.3, border_min_m=0.4)


def test_a_divider_is_carried_along_its_fitted_course_not_its_kinked_end() -> None:
    observed = np.zeros((100, 200), bool)  # 0.1 m cells, origin (0, 10): x 0..20 m, y 0..10 m
    observed[:, 20:140] = True  # seen from x = 2.0 to x = 13.9
    mask = ObservedMask(observed, (0.0, 10.0), 0.1)
    kinked = np.array(
        [[3.0, 5.0], [5.0, 5.0], [7.0, 5.0], [9.0, 5.0], [9.5, 5.3]]
    )  # last vertex pulled aside
    along_kink = carried_to_border(kinked, mask, 2.0, 6.0, 0.4)
    assert along_kink[-1, 1] > 7.5  # on along the kink's slope: metres off the line
    fitted = carried_to_border(kinked, mask, 2.0, 6.0, 0.4, fit_m=4.0, tolerance_m=0.15)
    assert len(fitted) == len(kinked) + 2  # the start's edge, 1 m behind it, is reached too
    # the kink tilts the fitted course a little (0.23 m over 4.4 m), against 2.6 m along the kink itself
    assert fitted[-1, 0] == pytest.approx(13.9, abs=0.051) and abs(fitted[-1, 1] - 5.0) < 0.25
    assert abs(fitted[-2, 1] - 5.0) < 0.15  # the kinked end put on the course first
    np.testing.assert_array_equal(fitted[1:-2], kinked[:-1])
    assert fitted[0] == pytest.approx([2.0, 5.0], abs=0.051)
    with pytest.raises(ValueError, match="divider_course_fit_m"):
        MaskInferenceConfig(divider_course_fit_m=-1.0)
    with pytest.raises(ValueError, match="divider_border_reach_m"):
        MaskInferenceConfig(divider_border_reach_m=0.3)


def test_correction_crops_centre_on_the_elements_and_the_road_between_them(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    divider = Vector("divider", np.array([global_xy(20, 20), global_xy(30, 20)]))
    alone = training_site("drawn", rasters, [divider], CONFIG, 0, 1, centres_on=[divider])
    with_road = training_site("drawn", rasters, [divider], CONFIG, 0, 1, centres_on=[divider], context_m=5.0)
    assert alone.road.shape[1] == 6  # points every 2 m along 10 m
    assert with_road.road.shape[1] == 12  # as many road cells again
    extra_rows, extra_cols = with_road.road[:, 6:] * CONFIG.resolution_m
    # within 5 m of the divider (y = 20 m, x 20..30 m) and on road (y 12..28 m)
    assert ((extra_cols > 14.5) & (extra_cols < 35.5) & (extra_rows > 11.9) & (extra_rows < 28.1)).all()


def test_an_element_reaching_the_rasters_last_cell_centres_crops_inside_the_grid(drawn_site: Path) -> None:
    # a point on the raster's far edge (x 59.95 m) lies half a cell of the network's coarser grid past the last
    # cell's centre, where rounding once gave a column one past the grid (the retrain job failed, IndexError)
    rasters = load_site_rasters(drawn_site)
    divider = Vector("divider", np.array([global_xy(50, 20), global_xy(59.95, 20)]))
    site = training_site("drawn", rasters, [divider], CONFIG, 0, 1, centres_on=[divider], context_m=5.0)
    rows, cols = site.road
    assert rows.size and (rows >= 0).all() and (cols >= 0).all()
    assert (rows < site.targets.shape[1]).all() and (cols < site.targets.shape[2]).all()
    assert cols.max() == site.targets.shape[2] - 1  # the end point's own cell is a crop centre


def _kerb_site(drawn_site: Path) -> tuple:
    """Road north of y = 20 m (rows above it), observed ground south of it, and a boundary probability band
    centred on the edge."""
    rasters = load_site_rasters(drawn_site)
    semantic = np.full(rasters.shape, int(Semantic.BACKGROUND), np.uint8)
    semantic[:200] = int(Semantic.ROAD)
    rows = np.arange(rasters.shape[0]) * rasters.resolution_m
    band = np.clip(1.0 - np.abs(rows - 20.0) / 0.4, 0.0, 1.0).astype(np.float32)
    probability = np.repeat(band[:, None], rasters.shape[1], axis=1)
    return replace(rasters, semantic=semantic), probability


def test_a_boundary_moves_off_the_road_by_the_outward_offset_and_a_line_in_the_road_stays(
    drawn_site: Path,
) -> None:
    rasters, probability = _kerb_site(drawn_site)
    traced = np.array([global_xy(5, 20.0), global_xy(55, 20.0)])
    normal = np.tile([[0.0, 1.0]], (2, 1))  # north, where the road is
    assert road_side(rasters, traced, normal).tolist() == [1.0, 1.0]
    assert road_side(rasters, traced, -normal).tolist() == [-1.0, -1.0]
    config = MaskInferenceConfig()
    kept = refined_line(rasters, probability, traced, config)
    moved = refined_line(rasters, probability, traced, config, outward_m=0.07)
    assert np.abs((ORIGIN_XY[1] - kept[:, 1]) - 20.0).max() < 0.01
    assert np.abs((ORIGIN_XY[1] - moved[:, 1]) - 20.07).max() < 0.01  # 7 cm south, off the road
    in_road = np.array([global_xy(5, 10.0), global_xy(55, 10.0)])  # road on both sides: nowhere to move to
    assert road_side(rasters, in_road, normal).tolist() == [0.0, 0.0]
    assert np.allclose(refined_line(rasters, probability, in_road, config, outward_m=0.07), in_road)


def test_boundaries_move_off_the_road_on_a_reconstruction_only(drawn_site: Path) -> None:
    rasters, band = _kerb_site(drawn_site)
    probabilities = np.zeros((len(CLASSES), *rasters.shape), np.float32)
    probabilities[CLASSES.index("boundary")] = band

    def boundary_y(site: SiteRasters) -> float:
        (vector,) = [v for v in vectors_from_probabilities(site, probabilities) if v.cls == "boundary"]
        line = LineString(vector.points)
        return float(ORIGIN_XY[1] - line.interpolate(0.5, normalized=True).y)

    assert boundary_y(replace(rasters, reconstructed=False)) == pytest.approx(20.0, abs=0.02)
    outward = MaskInferenceConfig().boundary_outward_m
    assert boundary_y(replace(rasters, reconstructed=True)) == pytest.approx(20.0 + outward, abs=0.02)
    with pytest.raises(ValueError, match="boundary_outward_m"):
        MaskInferenceConfig(boundary_outward_m=-0.1)


def test_a_network_rounded_to_the_stored_precision_proposes_as_its_saved_version(tmp_path: Path) -> None:
    torch.manual_seed(0)
    net = ElementMaskNet(MaskModelConfig(base_channels=4)).eval()
    image = torch.rand(1, net.config.in_channels, 32, 48)
    saved = load_mask_checkpoint(save_version(tmp_path / "registry", net, {"kind": KIND})).model
    with torch.no_grad():
        assert not torch.equal(net(image), saved(image))  # float32 weights: not the network that was saved
        assert torch.equal(round_to_stored(net)(image), saved(image))
