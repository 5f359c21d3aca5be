"""The gauge fit: a model with a perfect shape but a wrong placement is moved onto noisy odometry, so that
the odometry's per-clip drifts average out instead of being inherited."""

import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.gauge import GaugeSigmas, apply_gauge, fit_gauge
from cama_pipeline.sfm.guided import reconstruct_views
from tests.sfm.sfm_fixture import SfmInputs

SIGMAS = GaugeSigmas(position_m=0.15, tilt_deg=0.035, heading_deg=0.25)


def _pose(rotvec: np.ndarray, centre: np.ndarray) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    pose[:3, 3] = centre
    return pose


def _drive(clips: int = 4, frames: int = 40) -> dict[str, np.ndarray]:
    """True poses of a few straight clips driven in different directions across a 200 m site."""
    poses = {}
    for c in range(clips):
        heading = c * np.pi / clips
        for f in range(frames):
            centre = np.array([np.cos(heading), np.sin(heading), 0.0]) * (f * 2.5 - 50) + [c * 20.0, 0, 0]
            poses[f"clip{c}/{f}"] = _pose(np.array([0, 0, heading]), centre)
    return poses


def _moved(poses: dict[str, np.ndarray], transform: np.ndarray) -> dict[str, np.ndarray]:
    return {name: transform @ pose for name, pose in poses.items()}


def _errors(poses: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> tuple[float, float]:
    """Mean position (m) and rotation (deg) errors."""
    shifts = [np.linalg.norm(poses[n][:3, 3] - truth[n][:3, 3]) for n in truth]
    turns = [Rotation.from_matrix(poses[n][:3, :3] @ truth[n][:3, :3].T).magnitude() for n in truth]
    return float(np.mean(shifts)), float(np.degrees(np.mean(turns)))


def _clip_drifts(truth: dict[str, np.ndarray], seed: int = 3) -> dict[str, np.ndarray]:
    """Odometry: the truth with one constant 15 cm / 0.1-0.3 deg error per clip, plus small white noise."""
    rng = np.random.default_rng(seed)
    drift = {c: (rng.normal(0, 0.15, 3), rng.normal(0, np.radians([0.03, 0.03, 0.25]))) for c in range(4)}
    odometry = {}
    for name, pose in truth.items():
        shift, turn = drift[int(name[4])]
        noisy = pose.copy()
        noisy[:3, :3] = Rotation.from_rotvec(turn + rng.normal(0, 1e-4, 3)).as_matrix() @ pose[:3, :3]
        noisy[:3, 3] += shift + rng.normal(0, 0.01, 3)
        odometry[name] = noisy
    return odometry


def test_fit_recovers_a_known_rigid_offset() -> None:
    truth = _drive()
    offset = _pose(np.radians([0.1, -0.05, 0.3]), np.array([0.4, -0.3, 0.1]))
    fit = fit_gauge(_moved(truth, offset), truth, SIGMAS)
    assert fit is not None and fit.poses == len(truth)
    position, rotation = _errors(_moved(_moved(truth, offset), fit.new_from_old), truth)
    assert position < 1e-6 and rotation < 1e-6


def test_fit_averages_per_clip_drift_better_than_any_single_clip() -> None:
    """The fitted placement is closer to the truth than the odometry itself, and than a placement taken
    from one clip's odometry alone."""
    truth = _drive()
    odometry = _clip_drifts(truth)
    misplaced = _moved(truth, _pose(np.radians([0.2, 0.1, 1.0]), np.array([1.0, 2.0, 0.5])))
    fit = fit_gauge(misplaced, odometry, SIGMAS)
    assert fit is not None
    position, rotation = _errors(_moved(misplaced, fit.new_from_old), truth)
    odometry_position, odometry_rotation = _errors(odometry, truth)
    one_clip = {n: p for n, p in odometry.items() if n.startswith("clip0/")}
    single = fit_gauge(misplaced, one_clip, SIGMAS)
    assert single is not None
    single_position, _ = _errors(_moved(misplaced, single.new_from_old), truth)
    assert position < odometry_position and rotation < odometry_rotation
    assert position < single_position


def _scaled(poses: dict[str, np.ndarray], scale: float) -> dict[str, np.ndarray]:
    """The poses with their positions scaled about their mean (a model of the right shape, too small or large)."""
    centre = np.mean([pose[:3, 3] for pose in poses.values()], axis=0)
    scaled = {}
    for name, pose in poses.items():
        scaled[name] = pose.copy()
        scaled[name][:3, 3] = centre + scale * (pose[:3, 3] - centre)
    return scaled


def test_fit_with_scale_recovers_a_known_similarity() -> None:
    """A model 0.15 % too small and misplaced comes back exactly with `fit_scale`; the rigid fit keeps the
    scale, so its positions stay off by up to 0.15 % of the 100 m drive's half length."""
    truth = _drive()
    offset = _pose(np.radians([0.1, -0.05, 0.3]), np.array([0.4, -0.3, 0.1]))
    small = _moved(_scaled(truth, 1 / 1.0015), offset)
    fit = fit_gauge(small, truth, SIGMAS, fit_scale=True)
    assert fit is not None and fit.scale == pytest.approx(1.0015, abs=1e-9)
    assert fit.to_json()["scale"] == fit.scale
    position, rotation = _errors({n: fit.move_pose(p) for n, p in small.items()}, truth)
    assert position < 1e-6 and rotation < 1e-6
    rigid = fit_gauge(small, truth, SIGMAS)
    assert rigid is not None and rigid.scale == 1.0
    rigid_position, rigid_rotation = _errors({n: rigid.move_pose(p) for n, p in small.items()}, truth)
    assert 0.02 < rigid_position < 0.1 and rigid_rotation < 1e-6


def test_apply_and_move_pose_agree_on_a_similarity() -> None:
    """A scaled gauge moves a model's point (apply_gauge) and a pose at that point (move_pose) to the same
    place, and the moved pose keeps a proper rotation."""
    truth = _drive(clips=1, frames=5)
    fit = fit_gauge(_scaled(truth, 0.99), truth, SIGMAS, fit_scale=True)
    assert fit is not None
    model = pycolmap.Reconstruction()
    world_from_cam = _pose(np.radians([1.0, 2.0, 30.0]), np.array([3.0, -4.0, 1.5]))
    point_id = model.add_point3D(world_from_cam[:3, 3], pycolmap.Track())
    apply_gauge(model, fit.new_from_old)
    moved = fit.move_pose(world_from_cam)
    np.testing.assert_allclose(model.point3D(point_id).xyz, moved[:3, 3], atol=1e-9)
    np.testing.assert_allclose(moved[:3, :3] @ moved[:3, :3].T, np.eye(3), atol=1e-12)


def test_fit_needs_three_shared_poses() -> None:
    truth = _drive(clips=1, frames=2)
    assert fit_gauge(truth, truth, SIGMAS) is None
    assert fit_gauge(_drive(), {"elsewhere": np.eye(4)}, SIGMAS) is None


def test_apply_moves_points_and_frames_of_a_model() -> None:
    model = pycolmap.Reconstruction()
    point_id = model.add_point3D(np.array([1.0, 2.0, 3.0]), pycolmap.Track())
    transform = _pose(np.array([0, 0, np.pi / 2]), np.array([10.0, 0, 0]))
    apply_gauge(model, transform)
    np.testing.assert_allclose(model.point3D(point_id).xyz, [8.0, 1.0, 3.0], atol=1e-9)


@pytest.mark.parametrize("field", ["position_m", "tilt_deg", "heading_deg"])
def test_sigmas_must_be_positive(field: str) -> None:
    values = {"position_m": 0.1, "tilt_deg": 0.1, "heading_deg": 0.1, field: 0.0}
    with pytest.raises(ValueError, match=field):
        GaugeSigmas(**values)


def test_config_rejects_non_positive_gauge_sigma() -> None:
    with pytest.raises(ValueError, match="gauge_tilt_sigma_deg"):
        SfmConfig(gauge_tilt_sigma_deg=0)


@pytest.mark.slow
def test_reconstruction_is_placed_on_the_given_odometry(sfm_inputs: SfmInputs) -> None:
    """`odometry=` decides where the model goes (the merge passes every clip's WIGO poses): odometry shifted
    by 1 m moves the refined poses and the points by that metre, the shape unchanged."""
    views = sfm_inputs.longest_drive()
    config = SfmConfig.preset("rigid")
    plain = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config)
    shift = np.array([1.0, -0.5, 0.2])
    odometry = {v.name: v.world_from_ego + np.pad(shift[:, None], ((0, 1), (3, 0))) for v in views}
    moved = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config, odometry=odometry)
    assert moved.report["gauge"]["shift_m"] == pytest.approx(np.linalg.norm(shift), abs=0.01)
    offsets = np.array([moved.world_from_ego[n][:3, 3] - p[:3, 3] for n, p in plain.world_from_ego.items()])
    np.testing.assert_allclose(offsets, np.broadcast_to(shift, offsets.shape), atol=0.01)
    centre = np.mean([p.xyz for p in moved.reconstruction.points3D.values()], axis=0)
    plain_centre = np.mean([p.xyz for p in plain.reconstruction.points3D.values()], axis=0)
    np.testing.assert_allclose(centre - plain_centre, shift, atol=0.02)


@pytest.mark.slow
def test_scale_gauge_takes_the_scale_of_the_odometry(sfm_inputs: SfmInputs) -> None:
    """With `gauge_fit_scale` the model follows the odometry's scale: against odometry 0.3 % larger (scaled
    about its centre) the fit's scale and the spread of the refined poses both grow by 0.3 %."""
    views = sfm_inputs.longest_drive()
    centre = np.mean([v.world_from_ego[:3, 3] for v in views], axis=0)
    larger = {}
    for view in views:
        larger[view.name] = view.world_from_ego.copy()
        larger[view.name][:3, 3] = centre + 1.003 * (view.world_from_ego[:3, 3] - centre)
    config = SfmConfig.preset("rigid", gauge_fit_scale=True)

    def spread_and_scale(odometry: dict[str, np.ndarray] | None) -> tuple[float, float]:
        result = reconstruct_views(
            views, sfm_inputs.database, sfm_inputs.image_dir, config, odometry=odometry
        )
        positions = np.array([pose[:3, 3] for pose in result.world_from_ego.values()])
        radius = float(np.linalg.norm(positions - positions.mean(axis=0), axis=1).mean())
        return radius, result.report["gauge"]["scale"]

    radius, scale = spread_and_scale(None)
    larger_radius, larger_scale = spread_and_scale(larger)
    assert larger_scale / scale == pytest.approx(1.003, abs=1e-5)
    assert larger_radius / radius == pytest.approx(1.003, abs=1e-5)
