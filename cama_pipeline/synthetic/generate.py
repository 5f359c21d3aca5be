"""`cama synth`: generate a synthetic driving site as a nuScenes-layout data set plus its ground truth.

Output (`out_dir`):
    nuscenes/                 the data set (see cama_pipeline.data.schema), what the pipeline reads
    ground_truth/             what the pipeline is measured against, never read by it:
        vector_map.json       true elements (global metres, with z)
        baseline_map.json     a flawed 2D map (the paper's baseline)
        poses.json            true ego pose of every sample_data token
        bev/                  true BEV rasters, a raster folder (cama_pipeline.bev) with every layer
        semantic/, lane_instance/
                              only for a site made with `masks=False` (`cama synth --no-masks`): the per-image
                              masks, laid out as in a data set (`mask_relpath`), which then has none; exact, as
                              rendered: the config's mask noise (`masks`, which imitates an imperfect network's
                              masks shipped with a data set) is not applied, and the manifest's config says so
    manifest.json             config (a randomised site's drawn config, with its `random_seed`), location,
                              fingerprint and counts; written last, so its presence means complete;
                              `images_rendered` false marks a site made with `images=False` (`cama synth
                              --no-images`): every table, CAN file and ground-truth file is written, byte for byte
                              as a normal run would, but no camera image and no mask file (the tables still list
                              them, so a stage that reads images fails naming the missing file);
                              `masks_in_dataset` false: the masks are in ground_truth/, not in the data set;
                              `gnss` false: no `can_bus/<scene>_gnss.json` (real nuScenes has none; the
                              IMU and wheel files are those of a run with GNSS, byte for byte);
                              `logged_height` false: every ego_pose's z is 0, as nuScenes' 2D localization
                              logs it (`cama synth --no-logged-height`; the true poses keep their heights)

The whole tree is built in a sibling staging folder and renamed into place, so an interrupted run never
leaves a half-written site; a rerun with the same config finds the manifest and does nothing.
"""

import dataclasses
import hashlib
import json
import logging
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cama_pipeline.bev import BevRasters, write_bev
from cama_pipeline.data import Dataset, load_dataset
from cama_pipeline.data.masks import has_masks
from cama_pipeline.data.schema import GNSS_MESSAGE
from cama_pipeline.io import atomic_write_image, atomic_write_json
from cama_pipeline.progress import StageProgress
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from cama_pipeline.synthetic import ground_truth as gt
from cama_pipeline.synthetic.config import MaskNoiseConfig, SynthConfig
from cama_pipeline.synthetic.motion import TrueMotion, matrix_to_quat
from cama_pipeline.synthetic.render_jobs import render_all
from cama_pipeline.synthetic.sensors import coarse_ego_poses, simulate_can
from cama_pipeline.synthetic.site_model import SyntheticSite, build_synthetic_site, sub_rng
from cama_pipeline.synthetic.writer import NuScenesTables, make_token, write_can

logger = logging.getLogger(__name__)

GENERATOR_VERSION = 2
"""Bump when the generator's output changes for the same config, so old sites count as out of date."""
DATASET_DIR = "nuscenes"
GROUND_TRUTH_DIR = "ground_truth"
MANIFEST = "manifest.json"
SEED_SENSORS = 11


def truth_dataset(site: Path) -> Dataset:
    """A generated site's data set with the generator's true masks: the data set's own, or for a mask-free site
    (`cama synth --no-masks`) those kept in `<site>/ground_truth` (benchmarks score against them)."""
    root, truth = Path(site) / DATASET_DIR, Path(site) / GROUND_TRUTH_DIR
    return load_dataset(root, mask_roots=None if has_masks(root) or not truth.is_dir() else (truth,))


@dataclass(frozen=True)
class SynthResult:
    """Where a generated site is and what it holds."""

    out_dir: Path
    dataset_root: Path
    ground_truth_dir: Path
    version: str
    scenes: dict[str, str]
    """scene name -> kind (moving / stationary / night)."""
    images: int
    """Camera images the tables list (rendered or not)."""
    seconds: float
    skipped: bool
    images_rendered: bool = True
    """False for a site generated with `images=False`: its image and mask files do not exist."""
    masks_in_dataset: bool = True
    """False for a site generated with `masks=False`: its masks are under `ground_truth_dir`."""
    gnss: bool = True
    """False for a site generated with `gnss=False`: no GNSS CAN file."""
    logged_height: bool = True
    """False for a site generated with `logged_height=False`: every logged ego pose has z = 0."""

    @property
    def mask_root(self) -> Path:
        """The folder holding `semantic/` and `lane_instance/` (the data set, or ground truth for `masks=False`)."""
        return self.dataset_root if self.masks_in_dataset else self.ground_truth_dir


def fingerprint(
    cfg: SynthConfig,
    *,
    images: bool = True,
    masks: bool = True,
    gnss: bool = True,
    logged_height: bool = True,
) -> str:
    """Hash of everything that determines the output; a site without images, masks in the data set, GNSS or
    logged heights hashes apart from the full one, so that a later full run over it is never skipped as up to
    date."""
    content: dict[str, object] = {"config": dataclasses.asdict(cfg), "generator": GENERATOR_VERSION}
    for name, value in (
        ("images", images),
        ("masks", masks),
        ("gnss", gnss),
        ("logged_height", logged_height),
    ):
        if not value:
            content[name] = False
    payload = json.dumps(content, sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def run(
    cfg: SynthConfig,
    out_dir: Path,
    *,
    images: bool = True,
    masks: bool = True,
    gnss: bool = True,
    logged_height: bool = True,
    overwrite: bool = False,
    workers: int = 2,
    show_progress: bool = True,
) -> SynthResult:
    """Generate the site of `cfg` into `out_dir`, or do nothing if it is already there and up to date.

    `images=False` skips rendering (most of the time on big presets): tables, CAN and ground truth only, for
    work that needs poses but no pixels (the pairs benchmark). `masks=False` writes the masks into the
    ground truth instead of the data set, and `gnss=False` leaves out the GNSS CAN files (`cama synth
    --no-masks` does both: a data set as real nuScenes is). `logged_height=False` writes every logged ego pose
    with z = 0, as nuScenes' localization (2D) does; WIGO then leaves the height to the odometry. The manifest
    records all four. Masks in the ground truth are what the segmenter and SRE are scored against, so they are
    written without the config's mask noise.
    """
    out_dir = Path(out_dir)
    if not masks:
        cfg = dataclasses.replace(cfg, masks=MaskNoiseConfig())
    existing = _read_manifest(out_dir)
    digest = fingerprint(cfg, images=images, masks=masks, gnss=gnss, logged_height=logged_height)
    if existing is not None and existing.get("fingerprint") == digest and not overwrite:
        logger.info("%s is up to date; nothing to do", out_dir)
        return _result_from_manifest(out_dir, existing, skipped=True)
    if out_dir.exists() and any(out_dir.iterdir()) and existing is None and not overwrite:
        raise FileExistsError(
            f"{out_dir} exists, is not empty and is not a generated site; pass overwrite to replace it"
        )

    started = time.perf_counter()
    staging = out_dir.parent / f".{out_dir.name}.partial"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    site = build_synthetic_site(cfg)
    dataset_root = staging / DATASET_DIR
    true_poses = _write_tables_and_can(site, dataset_root, gnss=gnss, logged_height=logged_height)
    n_images = sum(len(site.schedules[clip.index].shots) for clip in site.clips)
    if images:
        mask_root = dataset_root if masks else staging / GROUND_TRUTH_DIR
        render_all(site, dataset_root, mask_root, workers, show_progress)
    else:
        logger.info("images not rendered (images=False): %d image files listed but absent", n_images)
    _write_ground_truth(site, staging / GROUND_TRUTH_DIR, true_poses, dataset_root, show_progress)
    scenes = {clip.name: clip.kind for clip in site.clips}
    manifest = {
        "fingerprint": digest,
        "preset": cfg.preset,
        "seed": cfg.seed,
        "random_seed": cfg.random_seed,
        "location": cfg.log_location,
        "version": cfg.version,
        "config": dataclasses.asdict(cfg),
        "scenes": scenes,
        "images": n_images,
        "images_rendered": images,
        "masks_in_dataset": masks,
        "gnss": gnss,
        "logged_height": logged_height,
        "seconds": round(time.perf_counter() - started, 2),
    }
    atomic_write_json(staging / MANIFEST, manifest, indent=2)
    _swap_into_place(staging, out_dir)
    return _result_from_manifest(out_dir, manifest, skipped=False)


def _read_manifest(out_dir: Path) -> dict | None:
    path = out_dir / MANIFEST
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError:
        return None


def _result_from_manifest(out_dir: Path, manifest: dict, *, skipped: bool) -> SynthResult:
    return SynthResult(
        out_dir,
        out_dir / DATASET_DIR,
        out_dir / GROUND_TRUTH_DIR,
        manifest["version"],
        manifest["scenes"],
        manifest["images"],
        manifest["seconds"],
        skipped,
        bool(manifest.get("images_rendered", True)),
        bool(manifest.get("masks_in_dataset", True)),
        bool(manifest.get("gnss", True)),
        bool(manifest.get("logged_height", True)),
    )


def _swap_into_place(staging: Path, out_dir: Path) -> None:
    """Replace `out_dir` by the finished staging tree (the old tree is removed only after the rename)."""
    if out_dir.exists():
        retired = out_dir.parent / f".{out_dir.name}.old"
        shutil.rmtree(retired, ignore_errors=True)
        out_dir.rename(retired)
        staging.rename(out_dir)
        shutil.rmtree(retired, ignore_errors=True)
    else:
        staging.rename(out_dir)


def _global_motion(motion: TrueMotion, origin_xy: tuple[float, float]) -> TrueMotion:
    """The same motion with positions in global coordinates."""
    shift = np.array([origin_xy[0], origin_xy[1], 0.0])
    return TrueMotion(motion.times_us, motion.global_from_ego_R, motion.global_from_ego_t + shift)


def _description(site: SyntheticSite, clip_index: int) -> str:
    clip = site.clips[clip_index]
    if clip.kind == "stationary":
        return "Day, stationary, waiting at the junction"
    return f"{'Night' if clip.kind == 'night' else 'Day'}, moving, route {clip.route_name}"


def _write_tables_and_can(
    site: SyntheticSite, dataset_root: Path, *, gnss: bool, logged_height: bool
) -> dict[str, dict]:
    """nuScenes tables with coarse ego poses (z = 0 unless `logged_height`), CAN messages per scene (GNSS only
    if `gnss`; both are simulated either way, so nothing else changes); returns the true pose per sample_data."""
    cfg = site.config
    tables = NuScenesTables(location=cfg.log_location)
    tables.add_rig(site.rig)
    true_poses: dict[str, dict] = {}
    for clip in site.clips:
        schedule = site.schedules[clip.index]
        motion = _global_motion(clip.motion, cfg.site_origin_xy)
        times = np.array([s.timestamp_us for s in schedule.shots])
        rng = sub_rng(cfg.seed, SEED_SENSORS, clip.index)
        coarse_R, coarse_t = coarse_ego_poses(motion, times, cfg.sensors, rng)
        if not logged_height:
            coarse_t = coarse_t * np.array([1.0, 1.0, 0.0])
        true_R, true_t = motion.interpolate(times)
        tables.add_clip(
            clip.name,
            site.log_name(clip.index),
            _description(site, clip.index),
            clip.start_time_us,
            schedule.sample_times_us,
            schedule.shots,
            coarse_R,
            coarse_t,
            (cfg.camera.width_px, cfg.camera.height_px),
        )
        messages = simulate_can(motion, cfg.sensors, rng)
        if not gnss:
            del messages[GNSS_MESSAGE]
        write_can(dataset_root, clip.name, messages)
        for i, shot in enumerate(schedule.shots):
            token = make_token(clip.name, "sample_data", shot.channel, shot.sweep_index)
            true_poses[token] = {
                "scene": clip.name,
                "channel": shot.channel,
                "timestamp": shot.timestamp_us,
                "is_key_frame": shot.is_key_frame,
                "rotation": [float(q) for q in matrix_to_quat(true_R[i])],
                "translation": [float(v) for v in true_t[i]],
            }
    tables.add_map("maps/drivable_area.png")
    tables.write(dataset_root / cfg.version)
    return true_poses


# ---- ground truth ----------------------------------------------------------------------------------


def _key_frame_cameras(site: SyntheticSite) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, int, int]]:
    cameras = []
    for clip in site.clips:
        for i, shot in enumerate(site.schedules[clip.index].shots):
            if shot.is_key_frame:
                view, _, _ = site.view(clip.index, i)
                cameras.append(
                    (view.layout_from_cam_R, view.layout_from_cam_t, view.K, view.width_px, view.height_px)
                )
    return cameras


def _write_ground_truth(
    site: SyntheticSite, gt_dir: Path, true_poses: dict[str, dict], dataset_root: Path, show_progress: bool
) -> None:
    """Vector map, baseline map, true poses and BEV rasters; also the data set's drivable-area prior."""
    cfg = site.config
    with StageProgress("synthetic ground truth", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("vector maps", total=4)
        vectors = gt.vector_map(site.layout, site.world, cfg.site_origin_xy)
        atomic_write_json(gt_dir / "vector_map.json", {"elements": vectors})
        baseline = gt.baseline_map(site.layout, cfg.site_origin_xy, sub_rng(cfg.seed, 21))
        atomic_write_json(gt_dir / "baseline_map.json", baseline)
        atomic_write_json(gt_dir / "poses.json", true_poses)
        progress.update(bar, advance=1, description="BEV rasters")
        grid = gt.bev_grid_for(site.world, cfg.bev_resolution_m)
        semantic, photometric, elevation = gt.render_bev(site.world, grid)
        progress.update(bar, advance=1, description="observation count")
        count = gt.observation_count(grid, elevation, _key_frame_cameras(site))
        progress.update(bar, advance=1, description="writing rasters")
        write_bev(
            gt_dir / "bev",
            BevRasters(
                grid.georeference(cfg.site_origin_xy),
                semantic=gt.unobserved_to_255(semantic, count),
                photometric_rgb=photometric,
                elevation=elevation,
                observation_count=count,
            ),
        )
        drivable = np.isin(semantic, ROAD_SURFACE_IDS)
        atomic_write_image(dataset_root / "maps" / "drivable_area.png", drivable.astype(np.uint8) * 255)
        progress.update(bar, advance=1, description="written")
