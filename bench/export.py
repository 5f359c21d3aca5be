"""Export benchmark: what a consumer of our CAMA release export measures when it reprojects the labels with the
exported odometry, in both SRE protocols (`strict`, ours; `cama`, CAMA's published metric code).

The export is read back as a consumer reads it (nothing from our side but the files): each scene's odometry
(`all_clips/<scene>/odometry/scmv_camera_<cam>.txt`, camera to world; world = global - the sidecar's world origin)
gives every image's ego pose, and each scene's labels (`maps/map_labels.json`, z from `vision_road_mlp_ft.npy` at
the point's cell, as CAMA's code reads them) give the map. Rows, all over the same images (the site's key-frame images SfM posed):

  ref            the true 3D map through the true poses (the floor set by the masks alone)
  a_truth        the true 3D map through the exported (refined) odometry; target: within 0.5 px of `ref`
  a_truth_sfm    the true 3D map through the SfM poses directly (a_truth minus this is what the export loses)
  a_truth_placed the true 3D map through the exported odometry after one rigid transform of the whole site onto
                 the true poses (a diagnostic split, not a result: a_truth minus this is what the site's global
                 placement costs, which comes from GNSS and the logged poses; this minus `ref` is the SfM shape)
  a_truth_labels the true map as exported (labels + elevation raster, cut per scene) through the exported odometry
  b_truth_coarse the true 3D map through the odometry of a `--poses coarse` export (the logged poses)
  c_pipeline     the pipeline's proposals exported (z from the exported elevation raster), read back from the
                 labels, through the exported odometry
  c_uncut        as c_pipeline with the per-scene cut switched off (`--observed-radius-m 1000`): c_pipeline minus
                 this is what cutting each scene's labels at its observed range costs
  c_uncut_observed  as c_uncut without the points on filled elevation cells: c_uncut minus this is what the
                 filled (unobserved) heights cost
  c_sfm          the same proposals lifted through our raster (as bench/end_to_end.py does) and projected with
                 the SfM poses directly: the figure before export

Usage: .venv/bin/python bench/export.py --site data/synthetic/default [--workspace W] [--out bench/results/export.json]
The site's workspace needs `cama run` up to proposals (the SfM poses, the surface rasters and the proposals).
"""

import argparse
import json
import platform
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from end_to_end import lifted_map  # bench/end_to_end.py: this script's folder is on sys.path
from scipy.spatial.transform import Rotation

from annotations import AnnotationSet, MapElement
from annotations.cama_cut import DEFAULT_OBSERVED_RADIUS_M
from annotations.cama_labels import CLASS_FROM_CAMA_TYPE
from annotations.cama_odometry import CAMERA_NAME_FROM_CHANNEL, timestamp_ms
from annotations.cama_sidecar import CamaReleaseGeoreference, read_sidecar
from cama_pipeline.bev import read_bev
from cama_pipeline.data import Dataset, Pose, Scene, load_dataset
from cama_pipeline.evaluate import SreConfig, SreProtocol, evaluate_sre, load_true_poses, load_vector_map
from cama_pipeline.evaluate.errors import pose_errors, umeyama_alignment
from cama_pipeline.evaluate.inputs import VectorElement
from cama_pipeline.evaluate.sre_report import ImageSre, SreReport
from cama_pipeline.export import ExportFormat, ExportRequest, PoseChoice, export
from cama_pipeline.refined_poses import site_scenes
from cama_pipeline.sfm.io import read_refined_poses
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.workspace import Workspace

RESULTS = Path(__file__).parent / "results"
UNCUT_RADIUS_M = 1000.0
"""An observed radius that keeps every element of a 600 m map: no per-scene cut."""
PROTOCOLS: tuple[SreProtocol, ...] = ("strict", "cama")


def reconstructed_site(workspace: Workspace) -> str:
    """The workspace's site with SfM poses and proposals (the first, when several)."""
    for site_id in read_site_ids(workspace.sites_index()):
        if workspace.sfm_poses(site_id).is_file() and workspace.proposals(site_id).is_file():
            return site_id
    raise SystemExit(f"{workspace.root}: no site with SfM poses and proposals; run `cama run` first")


def truth_set(site: Path, template: AnnotationSet) -> AnnotationSet:
    """The generator's true 3D map as an annotation set in the proposals' georeference (site coordinates)."""
    origin = np.asarray(template.georeference.site_origin_xy, dtype=float)
    elements = []
    for vector in load_vector_map(site / "ground_truth" / "vector_map.json"):
        xyz = np.asarray(vector.points, dtype=float)
        site_xyz = np.column_stack([xyz[:, :2] - origin, xyz[:, 2]])
        if vector.closed and not np.array_equal(site_xyz[0], site_xyz[-1]):
            site_xyz = np.vstack([site_xyz, site_xyz[:1]])
        elements.append(
            MapElement.model_validate(
                {
                    "id": vector.id,
                    "cls": vector.cls,
                    "points_2d": site_xyz[:, :2].tolist(),
                    "points_3d": site_xyz.tolist(),
                    "source": "human",
                    "review_state": "approved",
                }
            )
        )
    return AnnotationSet(site_id=template.site_id, georeference=template.georeference, elements=elements)


def global_vectors(annotations: AnnotationSet) -> list[VectorElement]:
    """An annotation set's 3D elements as the evaluator's global vectors (2D-only elements left out)."""
    origin = np.asarray(annotations.georeference.site_origin_xy, dtype=float)
    out = []
    for element in annotations.elements:
        xyz = element.xyz()
        if xyz is None or not np.isfinite(xyz).all():
            continue
        points = np.column_stack([xyz[:, :2] + origin, xyz[:, 2]])
        out.append(VectorElement(element.id, element.cls, points, element.cls == "ped_crossing"))
    return out


def read_scene_odometry(scene_dir: Path, scene: Scene) -> dict[str, Pose]:
    """Image token -> global_from_ego from one exported scene folder's clip-mode odometry, as a consumer would
    read it: rows by (camera, millisecond time) matched to the scene's images."""
    sidecar = read_sidecar(scene_dir / "maps" / "georeference.json")
    if not isinstance(sidecar, CamaReleaseGeoreference):
        raise SystemExit(f"{scene_dir}: not a release-layout scene folder (sidecar version 1)")
    origin = np.asarray(sidecar.world_origin_global, dtype=float)
    images = {(image.channel, timestamp_ms(image.timestamp_us)): image for image in scene.all_images()}
    poses = {}
    for channel, camera in CAMERA_NAME_FROM_CHANNEL.items():
        path = scene_dir / "odometry" / f"scmv_{camera}.txt"
        if not path.is_file():
            continue
        for line in path.read_text(encoding="utf-8").splitlines():
            t, x, y, z, qx, qy, qz, qw = (float(value) for value in line.split())
            image = images[(channel, round(t * 1000))]
            global_from_cam = Pose(np.array([x, y, z]) + origin, np.array([qw, qx, qy, qz]))
            poses[image.token] = global_from_cam @ image.calibration.ego_from_cam.inverse()
    return poses


def read_scene_labels(scene_dir: Path) -> tuple[list[VectorElement], list[VectorElement]]:
    """One exported scene's labels as CAMA's code reads them: x = v * r - S/2, y = u * r - S/2 in the world frame
    (plus the sidecar's world origin for global metres), z = the elevation raster at the point's cell [v, u]; and
    the same labels without the points on cells the export filled (our sidecar's PNG), as `cama import` reads them."""
    sidecar = read_sidecar(scene_dir / "maps" / "georeference.json")
    if not isinstance(sidecar, CamaReleaseGeoreference):
        raise SystemExit(f"{scene_dir}: not a release-layout scene folder (sidecar version 1)")
    elevation = np.load(scene_dir / "maps" / "vision_road_mlp_ft.npy", mmap_mode="r")
    labels = json.loads((scene_dir / "maps" / "map_labels.json").read_text(encoding="utf-8"))
    half, r = sidecar.map_side_m / 2, sidecar.resolution_m
    origin = np.asarray(sidecar.world_origin_global[:2], dtype=float)
    filled = cv2.imread(str(scene_dir / "maps" / sidecar.elevation_filled), cv2.IMREAD_UNCHANGED)
    if filled is None:
        raise SystemExit(f"{scene_dir}: cannot read maps/{sidecar.elevation_filled}")
    out, observed = [], []
    for index, instance in enumerate(labels):
        cls = CLASS_FROM_CAMA_TYPE.get(instance["attrs"]["type"])
        if cls is None:
            continue
        uv = np.asarray(instance["data"], dtype=float)
        rows = np.clip(np.rint(uv[:, 1]).astype(int), 0, elevation.shape[0] - 1)
        cols = np.clip(np.rint(uv[:, 0]).astype(int), 0, elevation.shape[1] - 1)
        xy = np.column_stack([uv[:, 1] * r - half, uv[:, 0] * r - half]) + origin
        points = np.column_stack([xy, elevation[rows, cols]])
        name, closed = f"{instance['id']}-{index}", cls == "ped_crossing"
        out.append(VectorElement(name, cls, points, closed))
        seen = points[filled[rows, cols] == 0]
        if len(seen) >= 2:
            observed.append(VectorElement(name, cls, seen, closed))
    return out, observed


def read_export(
    out: Path, dataset: Dataset
) -> tuple[dict[str, Pose], dict[str, list[VectorElement]], dict[str, list[VectorElement]]]:
    """Every exported scene's odometry poses (merged), labels (per scene) and labels without the points on filled
    elevation cells (per scene)."""
    scenes = {scene.name: scene for scene in dataset.scenes}
    poses: dict[str, Pose] = {}
    labels: dict[str, list[VectorElement]] = {}
    observed: dict[str, list[VectorElement]] = {}
    for scene_dir in sorted((out / "all_clips").iterdir()):
        poses.update(read_scene_odometry(scene_dir, scenes[scene_dir.name]))
        labels[scene_dir.name], observed[scene_dir.name] = read_scene_labels(scene_dir)
    return poses, labels, observed


def sre_row(
    dataset: Dataset,
    maps: Mapping[str, Sequence[VectorElement]],
    poses: Mapping[str, Pose],
    images: set[str],
    protocol: SreProtocol,
) -> dict[str, Any]:
    """SRE / P / R / F1 of per-scene maps over the chosen images, one report over every scene's images."""
    config = SreConfig(protocol=protocol)
    results: list[ImageSre] = []
    for scene, elements in maps.items():
        report = evaluate_sre(dataset, elements, config, true_poses=poses, scenes=[scene], images=images)
        results.extend(report.images)
    return dict(vars(SreReport.from_images(results, config).overall))


def placed_on_truth(poses: Mapping[str, Pose], truth: Mapping[str, Pose]) -> tuple[dict[str, Pose], dict]:
    """`poses` moved by the one rigid transform that best fits them onto `truth` (positions and orientations:
    each pose contributes its origin and the tips of its unit axes), and what the move was."""
    tokens = sorted(set(poses) & set(truth))

    def axis_points(pose: Pose) -> np.ndarray:
        return pose.translation + np.vstack([np.zeros(3), pose.rotation_matrix().T])

    source = np.vstack([axis_points(poses[t]) for t in tokens])
    target = np.vstack([axis_points(truth[t]) for t in tokens])
    rotation, translation, _ = umeyama_alignment(source, target, with_scale=False)
    turn = Rotation.from_matrix(rotation)
    placed = {
        token: Pose(
            rotation @ pose.translation + translation,
            (turn * Rotation.from_quat(pose.rotation, scalar_first=True)).as_quat(scalar_first=True),
        )
        for token, pose in poses.items()
    }
    before = pose_errors([poses[t] for t in tokens], [truth[t] for t in tokens])
    after = pose_errors([placed[t] for t in tokens], [truth[t] for t in tokens])
    move = {
        "poses": len(tokens),
        "turn_deg": float(np.degrees(turn.magnitude())),
        "tilt_deg": float(np.degrees(np.linalg.norm(turn.as_rotvec()[:2]))),
        "yaw_deg": float(np.degrees(turn.as_rotvec()[2])),
        "shift_cm": [round(100 * v, 2) for v in translation + rotation @ source.mean(0) - source.mean(0)],
        "position_rmse_cm_before": round(100 * before.position_rmse_m, 2),
        "rotation_rmse_deg_before": round(before.rotation_rmse_deg, 4),
        "position_rmse_cm_after": round(100 * after.position_rmse_m, 2),
        "rotation_rmse_deg_after": round(after.rotation_rmse_deg, 4),
    }
    return placed, move


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--workspace", type=Path, default=None, help="default: the site's workspace")
    parser.add_argument("--out", type=Path, default=RESULTS / "export.json")
    args = parser.parse_args()
    dataset_root = args.site / "nuscenes"
    workspace = Workspace.resolve(args.workspace, dataset_root)
    dataset = load_dataset(dataset_root)
    site_id = reconstructed_site(workspace)
    scenes = site_scenes(workspace, site_id)
    proposals = AnnotationSet.read_json(workspace.proposals(site_id))
    elevation = (
        read_bev(workspace.surface_bev(site_id), ["elevation"]).require("elevation").astype(np.float64)
    )
    truth = truth_set(args.site, proposals)
    origin = np.asarray(proposals.georeference.site_origin_xy, dtype=float)
    pipeline_lifted = lifted_map(
        [(e.cls, e.xy() + origin) for e in proposals.elements], workspace.surface_bev(site_id)
    )
    sfm = read_refined_poses(workspace.sfm_poses(site_id))
    images = {
        image.token
        for scene in dataset.scenes
        if scene.name in scenes
        for frame in scene.frames
        for image in frame.images.values()
        if image.token in sfm
    }
    timings: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="cama-export-bench-") as tmp:
        exported = {}
        for name, annotations, choice, radius in (
            ("truth_refined", truth, PoseChoice.refined, DEFAULT_OBSERVED_RADIUS_M),
            ("truth_coarse", truth, PoseChoice.coarse, DEFAULT_OBSERVED_RADIUS_M),
            ("pipeline_refined", proposals, PoseChoice.refined, DEFAULT_OBSERVED_RADIUS_M),
            ("pipeline_uncut", proposals, PoseChoice.refined, UNCUT_RADIUS_M),
        ):
            started = time.perf_counter()
            request = ExportRequest(
                annotations,
                Path(tmp) / name,
                format=ExportFormat.cama,
                dataset_root=dataset_root,
                workspace=workspace.root,
                site_id=site_id,
                poses=choice,
                elevation=elevation,
                observed_radius_m=radius,
            )
            exported[name] = read_export(export(request).path, dataset)
            timings[name] = round(time.perf_counter() - started, 2)
    true_map = {scene: global_vectors(truth) for scene in scenes}
    sfm_poses = {
        token: Pose(matrix[:3, 3], Rotation.from_matrix(matrix[:3, :3]).as_quat(scalar_first=True))
        for token, matrix in sfm.items()
    }
    true_poses = load_true_poses(args.site / "ground_truth" / "poses.json")
    placed, placement = placed_on_truth(exported["truth_refined"][0], true_poses)
    rows = {
        "ref": (true_map, true_poses),
        "a_truth": (true_map, exported["truth_refined"][0]),
        "a_truth_sfm": (true_map, sfm_poses),
        "a_truth_placed": (true_map, placed),
        "a_truth_labels": (exported["truth_refined"][1], exported["truth_refined"][0]),
        "b_truth_coarse": (true_map, exported["truth_coarse"][0]),
        "c_pipeline": (exported["pipeline_refined"][1], exported["pipeline_refined"][0]),
        "c_uncut": (exported["pipeline_uncut"][1], exported["pipeline_uncut"][0]),
        "c_uncut_observed": (exported["pipeline_uncut"][2], exported["pipeline_uncut"][0]),
        "c_sfm": ({scene: pipeline_lifted for scene in scenes}, sfm_poses),
    }
    figures: dict[str, Any] = {"site": str(args.site), "site_id": site_id, "scenes": scenes}
    figures["images"] = len(images)
    figures["export_seconds"] = timings
    figures["placement_of_exported_poses"] = placement
    for protocol in PROTOCOLS:
        figures[protocol] = {
            name: sre_row(dataset, maps, poses, images, protocol) for name, (maps, poses) in rows.items()
        }
        ref = figures[protocol]["ref"]["sre_ref_px"]
        got = figures[protocol]["a_truth"]["sre_ref_px"]
        figures[protocol]["a_minus_ref_px"] = None if ref is None or got is None else got - ref
        placed_px = figures[protocol]["a_truth_placed"]["sre_ref_px"]
        figures[protocol]["a_placed_minus_ref_px"] = (
            None if ref is None or placed_px is None else placed_px - ref
        )
    figures["command"] = "python bench/export.py " + " ".join(sys.argv[1:])
    figures["machine"] = {"python": platform.python_version(), "time": time.strftime("%Y-%m-%d %H:%M")}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=1, default=float) + "\n")
    for protocol in PROTOCOLS:
        for name, row in figures[protocol].items():
            if isinstance(row, dict):
                print(
                    f"{protocol:6s} {name:15s} SRE {row['sre_ref_px']} px  P {row['precision']}  "
                    f"R {row['recall']}  F1 {row['f1']}"
                )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
