"""The generated tiny site: layout on disk, loader round trip, timing, masks, ground truth and baseline."""

import json

import cv2
import numpy as np
from shapely.geometry import Point

from cama_pipeline.data import load_dataset
from cama_pipeline.data.schema import CAMERA_CHANNELS
from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic.layout import build_layout
from cama_pipeline.synthetic.motion import quat_to_matrix
from cama_pipeline.synthetic.realism import road_sift_inliers


def _true_global_from_cam(site, image):
    """True global_from_cam (R, t) of a loaded CameraImage, from ground_truth/poses.json."""
    poses = site.__dict__.setdefault(
        "_poses", json.loads((site.result.ground_truth_dir / "poses.json").read_text())
    )
    pose = poses[image.token]
    R_ego = quat_to_matrix(np.asarray(pose["rotation"]))
    t_ego = np.asarray(pose["translation"])
    ego_from_cam = image.calibration.ego_from_cam
    return R_ego @ ego_from_cam.rotation_matrix(), R_ego @ ego_from_cam.translation + t_ego


def test_nuscenes_layout_on_disk(site_root):
    root = site_root / "nuscenes"
    version = root / "v1.0-synth"
    for table in ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor", "sensor", "log", "map"):
        assert (version / f"{table}.json").is_file(), table
    for channel in CAMERA_CHANNELS:
        assert any((root / "samples" / channel).glob("*.jpg")), channel
        assert any((root / "sweeps" / channel).glob("*.jpg")), channel
    assert sorted(p.name.split("_", 1)[1] for p in (root / "can_bus").glob("scene-0001_*.json")) == [
        "gnss.json",
        "ms_imu.json",
        "zoe_veh_info.json",
    ]
    assert (site_root / "ground_truth" / "vector_map.json").is_file()
    assert not (root / "ground_truth").exists(), "ground truth must stay outside the data set"


def test_loader_round_trip(tiny_site):
    dataset = load_dataset(tiny_site.result.dataset_root)
    manifest = json.loads((tiny_site.result.out_dir / "manifest.json").read_text())
    assert {s.name for s in dataset.scenes} == set(manifest["scenes"])
    assert sum(len(s.all_images()) for s in dataset.scenes) == manifest["images"]
    poses = json.loads((tiny_site.result.ground_truth_dir / "poses.json").read_text())
    for scene in dataset.scenes:
        assert set(scene.channels) == set(CAMERA_CHANNELS)
        assert scene.can.imu is not None and scene.can.wheel is not None and scene.can.gnss is not None
        for frame in scene.frames:
            assert set(frame.images) == set(CAMERA_CHANNELS)
            stamps = [im.timestamp_us for im in frame.images.values()]
            assert max(stamps) - min(stamps) <= 50_000, "key frames of one sample fire within 50 ms"
        front = scene.images["CAM_FRONT"]
        gaps_ms = np.diff([im.timestamp_us for im in front]) / 1000
        assert np.allclose(gaps_ms, 1000 / 12, atol=1), "cameras sweep at 12 Hz"
        errors = [
            np.linalg.norm(im.global_from_ego.translation - poses[im.token]["translation"]) for im in front
        ]
        assert 0.0 < max(errors) < 3.0, "ego_pose is coarse: close to, never equal to, the truth"
    image = dataset.scenes[0].frames[0].images["CAM_FRONT"]
    rgb = image.load_rgb()
    assert rgb.shape == (tiny_site.config.camera.height_px, tiny_site.config.camera.width_px, 3)
    assert image.load_semantic().shape == rgb.shape[:2]


def test_camera_offsets_differ_per_camera(tiny_site):
    scene = load_dataset(tiny_site.result.dataset_root).scenes[0]
    first = {ch: scene.images[ch][0].timestamp_us for ch in CAMERA_CHANNELS}
    assert len(set(first.values())) == 6
    assert max(first.values()) - min(first.values()) >= 20_000


def _project(points, R_cam, t_cam, K):
    cam = (points - t_cam) @ R_cam
    uv = cam @ K.T
    return uv[:, :2] / uv[:, 2:3], cam[:, 2]


def _label_hits(site, dataset, points_global, label):
    """Fraction of (visible, unoccluded-by-vehicles) projections of `points_global` on pixels of `label`."""
    hits = total = 0
    for scene in dataset.scenes:
        if scene.description.startswith("Night"):
            continue
        for frame in scene.frames:
            for image in frame.images.values():
                R, t = _true_global_from_cam(site, image)
                uv, depth = _project(points_global, R, t, image.calibration.intrinsic)
                ok = (depth > 3) & (depth < 15)
                ok &= (uv[:, 0] >= 2) & (uv[:, 0] < image.calibration.width - 2)
                ok &= (uv[:, 1] >= 2) & (uv[:, 1] < image.calibration.height - 2)
                if not ok.any():
                    continue
                semantic = image.load_semantic()
                px = np.round(uv[ok]).astype(int)
                occluded = np.isin(semantic[px[:, 1], px[:, 0]], [Semantic.VEHICLE, Semantic.STATIC_OBJECT])
                px = px[~occluded]
                # a 3x3 neighbourhood: thin paint is 2-3 px wide at the tiny preset's resolution
                near = np.stack(
                    [semantic[px[:, 1] + dv, px[:, 0] + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)]
                )
                hits += int((near == label).any(axis=0).sum())
                total += px.shape[0]
    assert total > 50, "too few projections to judge"
    return hits / total


def test_marking_and_curb_points_project_onto_their_labels(tiny_site):
    dataset = load_dataset(tiny_site.result.dataset_root)
    elements = json.loads((tiny_site.result.ground_truth_dir / "vector_map.json").read_text())["elements"]
    solid = [e for e in elements if e["class"] == "divider" and e["style"] == "solid"]
    marking_points = np.array([p for e in solid for p in e["points"][1:-1]])
    assert _label_hits(tiny_site, dataset, marking_points, Semantic.LANE_MARKING) > 0.9

    cfg = tiny_site.config
    layout = build_layout(cfg.layout)
    origin = np.array([*cfg.site_origin_xy, 0.0])
    curb_points = []
    for e in (e for e in elements if e["class"] == "boundary"):
        pts = np.asarray(e["points"]) - origin
        for a, b in zip(pts[:-1], pts[1:], strict=True):
            mid = (a + b) / 2
            normal = np.array([-(b - a)[1], (b - a)[0], 0.0]) / max(np.linalg.norm((b - a)[:2]), 1e-9)
            for side in (-1, 1):
                p = mid + side * 0.1 * normal
                if layout.curb_strip.contains(Point(p[0], p[1])):
                    curb_points.append(p + origin + [0, 0, cfg.layout.curb_height_m])
    assert _label_hits(tiny_site, dataset, np.array(curb_points), Semantic.CURB) > 0.8


def test_trunk_visible_only_in_back_camera(tiny_site):
    scene = load_dataset(tiny_site.result.dataset_root).scenes[0]
    back = scene.frames[0].images["CAM_BACK"].load_semantic()
    front = scene.frames[0].images["CAM_FRONT"].load_semantic()
    assert (back == Semantic.EGO).mean() > 0.03
    assert (back[-3:] == Semantic.EGO).mean() > 0.5, "the trunk sits at the bottom of CAM_BACK"
    assert (front == Semantic.EGO).mean() == 0.0


def test_night_clip_is_dark_and_low_contrast(tiny_site):
    dataset = load_dataset(tiny_site.result.dataset_root)
    night = next(s for s in dataset.scenes if s.description.startswith("Night"))
    day = next(s for s in dataset.scenes if s.description.startswith("Day"))
    night_img = night.frames[0].images["CAM_FRONT"].load_rgb().astype(float)
    day_img = day.frames[0].images["CAM_FRONT"].load_rgb().astype(float)
    assert night_img.mean() < 0.3 * day_img.mean()
    assert night_img.std() < 0.3 * day_img.std()


def test_stationary_clip_does_not_move(tiny_site):
    dataset = load_dataset(tiny_site.result.dataset_root)
    poses = json.loads((tiny_site.result.ground_truth_dir / "poses.json").read_text())
    still = next(s for s in dataset.scenes if "stationary" in s.description)
    xyz = np.array([poses[im.token]["translation"] for im in still.images["CAM_FRONT"]])
    assert np.ptp(xyz, axis=0).max() < 1e-6


def test_sift_matches_on_the_road_between_sweeps(tiny_site):
    """Consecutive front images share geometrically verified SIFT matches on road pixels (what SfM needs)."""
    scene = load_dataset(tiny_site.result.dataset_root).scenes[0]
    images = scene.images["CAM_FRONT"]
    counts = [
        road_sift_inliers(a.load_rgb(), b.load_rgb(), a.load_semantic())
        for a, b in zip(images[:4], images[2:6], strict=False)
    ]
    # 256x144 images: a textureless road gives ~0; this texture gives 9-20 per pair
    assert np.median(counts) >= 10 and min(counts) >= 5, counts


def test_bev_rasters_follow_the_georeference(tiny_site):
    gt_dir = tiny_site.result.ground_truth_dir
    geo = json.loads((gt_dir / "bev" / "georeference.json").read_text())
    semantic = cv2.imread(str(gt_dir / "bev" / "semantic.png"), cv2.IMREAD_UNCHANGED)
    elevation = np.load(gt_dir / "bev" / "elevation.npy")
    count = cv2.imread(str(gt_dir / "bev" / "observation_count.png"), cv2.IMREAD_UNCHANGED)
    assert semantic.shape == elevation.shape == count.shape == (geo["height"], geo["width"])
    assert set(np.unique(semantic)) <= {0, 1, 2, 3, 4, 255}
    assert ((semantic == 255) == (count == 0)).all()
    elements = json.loads((gt_dir / "vector_map.json").read_text())["elements"]

    def cell(x, y):
        col = round((x - geo["origin_xy"][0]) / geo["resolution"])
        row = round((geo["origin_xy"][1] - y) / geo["resolution"])
        return row, col

    crossing = next(e for e in elements if e["class"] == "ped_crossing")
    pts = np.asarray(crossing["points"])
    labels = [semantic[cell(x, y)] for x, y in pts[:, :2] * 0.5 + pts[:, :2].mean(axis=0) * 0.5]
    assert labels.count(Semantic.CROSSWALK) + labels.count(Semantic.ROAD) == len(labels)
    for e in elements[:5]:
        for x, y, z in e["points"][:3]:
            assert abs(elevation[cell(x, y)] - z) < 0.05
    zs = np.array([p[2] for e in elements for p in e["points"]])
    assert np.ptp(zs) > 1.0, "terrain rises over the site"


def test_baseline_map_is_flawed_like_the_papers(tiny_site):
    gt_dir = tiny_site.result.ground_truth_dir
    baseline = json.loads((gt_dir / "baseline_map.json").read_text())
    truth = json.loads((gt_dir / "vector_map.json").read_text())["elements"]
    assert all(len(p) == 2 for e in baseline["elements"] for p in e["points"]), "no elevation"
    assert any(e["source"] == "rule" for e in baseline["elements"])
    kept = {e["id"].replace("base-", "gt-") for e in baseline["elements"] if e["source"] == "survey"}
    missing = {e["id"] for e in truth} - kept
    assert missing == set(baseline["flaws"]["missing_ids"]) and 1 <= len(missing) <= 2
    by_id = {e["id"]: e for e in truth}
    survey = next(e for e in baseline["elements"] if e["source"] == "survey")
    shift = np.asarray(survey["points"][0]) - np.asarray(
        by_id[survey["id"].replace("base-", "gt-")]["points"][0][:2]
    )
    assert 0.2 < np.linalg.norm(shift) < 1.5
