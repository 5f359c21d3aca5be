"""Loading a data set of nuScenes v1.0-trainval's size: seconds and memory of `load_dataset`, whole and by scene.

Real trainval holds 850 scenes, 34,149 samples and 2,631,083 sample_data and ego_pose records (camera images at
12 Hz with their sweeps, lidar at 20 Hz, five radars at 13 Hz), 1.3 GB of sample_data.json. No such data is on
this machine and nothing is downloaded, so the bench writes tables of that size and form (`--scenes`, 40 samples
a scene, 20 s of each sensor at its rate, `indent=0` as nuScenes writes them, tokens of 32 hex digits drawn
from a seeded generator, written by a process of its own) and no images (`check_files=False`). Every measurement
runs in a fresh Python process after the tables have been read once (so each finds them in the page cache) and
reports its wall seconds, its peak resident memory (`VmHWM`: it counts the pages of a memory-mapped table it
touched, which the kernel can drop at any time) and its anonymous resident memory once loaded (`RssAnon`: what the
process holds on to, the parsed tables or the data set):
  whole_parse        `json.load` of the seven required tables: what any loader that parses them whole pays before
                     it builds anything (the loader before `cama_pipeline/data/selection.py` did this);
  baseline_loader    `load_dataset` of another checkout (`--baseline-code DIR`, e.g. a `git worktree` of the
                     commit before), the baseline of the ratios;
  all_scenes         `load_dataset(root)`: every scene's camera images;
  scenes_N           `load_dataset(root, scenes=...)` of N scenes (`--subsets`, e.g. one scene, a site of ten).

Usage: .venv/bin/python bench/loader.py [--tables DIR] [--scenes 850] [--subsets 1,10]
       [--baseline-code DIR] [--out bench/results/loader_trainval.json]
"""

import argparse
import json
import multiprocessing
import os
import platform
import random
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from cama_pipeline.data.schema import CAMERA_CHANNELS, REQUIRED_TABLES
from cama_pipeline.io import atomic_write_json

RESULTS = Path(__file__).parent / "results"
ROOT = Path(__file__).resolve().parents[1]
VERSION = "v1.0-trainval"
SAMPLES_PER_SCENE = 40
SCENE_SECONDS = 20
SENSORS: tuple[tuple[str, str, int], ...] = (
    *((channel, "camera", 12) for channel in CAMERA_CHANNELS),
    ("LIDAR_TOP", "lidar", 20),
    *(
        (f"RADAR_{side}", "radar", 13)
        for side in ("FRONT", "FRONT_LEFT", "FRONT_RIGHT", "BACK_LEFT", "BACK_RIGHT")
    ),
)
"""(channel, modality, Hz) of nuScenes' sensors."""
LOGS = 68
INTRINSIC = [[1266.4, 0.0, 816.3], [0.0, 1266.4, 491.5], [0.0, 0.0, 1.0]]

MEASURE = """
import json, sys, time
from pathlib import Path
mode, root, names, version = sys.argv[1], Path(sys.argv[2]), json.loads(sys.argv[3]), sys.argv[4]
started = time.perf_counter()
if mode == "whole_parse":
    tables = []
    for name in names:
        with open(root / version / f"{name}.json", encoding="utf-8") as handle:
            tables.append(json.load(handle))
    images = None
else:
    from cama_pipeline.data import load_dataset
    dataset = load_dataset(root, check_files=False, **({} if names is None else {"scenes": names}))
    images = sum(1 for _ in dataset.camera_images())
seconds = time.perf_counter() - started
status = {l.split(":")[0]: int(l.split()[1]) for l in open("/proc/self/status") if l.startswith(("RssAnon", "VmHWM"))}
print(json.dumps(
    {"seconds": seconds, "peak_rss_mb": status["VmHWM"] / 1024, "rss_anon_mb": status["RssAnon"] / 1024, "images": images}
))
"""


class Tokens:
    """32-hex-digit tokens from a seeded generator, as nuScenes' look."""

    def __init__(self, seed: int) -> None:
        self.random = random.Random(seed)

    def __call__(self) -> str:
        return f"{self.random.getrandbits(128):032x}"


def write_tables(version_dir: Path, scenes: int, seed: int = 0) -> dict[str, int]:
    """Tables of `scenes` scenes in nuScenes' form (see the module docstring); the record count per table."""
    token = Tokens(seed)
    sensors = [{"token": token(), "channel": c, "modality": m} for c, m, _ in SENSORS]
    locations = ("boston-seaport", "singapore-onenorth", "singapore-queenstown", "singapore-hollandvillage")
    logs = [
        {
            "token": token(),
            "logfile": f"n015-2018-07-{i % 28 + 1:02d}-11-00-00+0800",
            "vehicle": "n015",
            "date_captured": "2018-07-24",
            "location": locations[i % len(locations)],
        }
        for i in range(LOGS)
    ]
    tables: dict[str, list[dict[str, Any]]] = {name: [] for name in REQUIRED_TABLES}
    tables["sensor"], tables["log"] = sensors, logs
    start_us = 1_532_402_927_000_000
    for s in range(scenes):
        _write_scene(tables, token, s, logs[s % LOGS]["token"], sensors, start_us + s * 3_600_000_000)
    version_dir.mkdir(parents=True, exist_ok=True)
    for name, records in tables.items():
        (version_dir / f"{name}.json").write_text(json.dumps(records, indent=0))
    return {name: len(records) for name, records in tables.items()}


def _write_scene(
    tables: dict[str, list[dict[str, Any]]],
    token: Tokens,
    index: int,
    log_token: str,
    sensors: list[dict[str, Any]],
    start_us: int,
) -> None:
    """One scene's records: calibrations, samples every 0.5 s, each sensor's sample_data and ego poses."""
    calibrated = {}
    for sensor in sensors:
        record = {
            "token": token(),
            "sensor_token": sensor["token"],
            "translation": [1.5, 0.0, 1.6],
            "rotation": [0.5, -0.5, 0.5, -0.5],
            "camera_intrinsic": INTRINSIC if sensor["modality"] == "camera" else [],
        }
        tables["calibrated_sensor"].append(record)
        calibrated[sensor["channel"]] = record["token"]
    samples = [token() for _ in range(SAMPLES_PER_SCENE)]
    scene = {
        "token": token(),
        "log_token": log_token,
        "nbr_samples": SAMPLES_PER_SCENE,
        "first_sample_token": samples[0],
        "last_sample_token": samples[-1],
        "name": f"scene-{index + 1:04d}",
        "description": "Wait at intersection, peds, trucks",
    }
    tables["scene"].append(scene)
    for i, sample in enumerate(samples):
        tables["sample"].append(
            {
                "token": sample,
                "timestamp": start_us + i * 500_000,
                "prev": samples[i - 1] if i else "",
                "next": samples[i + 1] if i + 1 < len(samples) else "",
                "scene_token": scene["token"],
            }
        )
    for channel, modality, hz in SENSORS:
        previous: dict[str, Any] | None = None
        per_sample = hz // 2
        for j in range(SCENE_SECONDS * hz):
            timestamp = start_us + j * 1_000_000 // hz
            key_frame = j % per_sample == 0
            pose = {
                "token": token(),
                "timestamp": timestamp,
                "rotation": [0.57, -0.0, 0.01, -0.82],
                "translation": [411.3 + j * 0.4, 1180.9, 0.0],
            }
            tables["ego_pose"].append(pose)
            extension = "jpg" if modality == "camera" else ("pcd.bin" if modality == "lidar" else "pcd")
            record = {
                "token": token(),
                "sample_token": samples[min(j // per_sample, SAMPLES_PER_SCENE - 1)],
                "ego_pose_token": pose["token"],
                "calibrated_sensor_token": calibrated[channel],
                "timestamp": timestamp,
                "fileformat": extension.split(".")[0],
                "is_key_frame": key_frame,
                "height": 900 if modality == "camera" else 0,
                "width": 1600 if modality == "camera" else 0,
                "filename": f"{'samples' if key_frame else 'sweeps'}/{channel}/"
                f"n015-2018-07-24-11-22-45+0800__{channel}__{timestamp}.{extension}",
                "prev": previous["token"] if previous else "",
                "next": "",
            }
            if previous is not None:
                previous["next"] = record["token"]
            tables["sample_data"].append(record)
            previous = record


def ensure_tables(root: Path, scenes: int) -> dict[str, int]:
    """The tables of `scenes` scenes in `root`'s version folder: reused when an earlier run wrote that many (its
    `counts.json`), else written in a process of its own, whose memory is returned before the measurements; the
    record count per table."""
    version_dir = root / VERSION
    counts_path = version_dir / "counts.json"
    if counts_path.is_file() and json.loads(counts_path.read_text())["scenes"] == scenes:
        return dict(json.loads(counts_path.read_text())["records"])
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        counts = pool.submit(write_tables, version_dir, scenes).result()
    counts_path.write_text(json.dumps({"scenes": scenes, "records": counts}))
    return counts


def warm_page_cache(root: Path) -> None:
    """Read every table once, so that each measurement finds them in the page cache."""
    for path in sorted((root / VERSION).glob("*.json")):
        with open(path, "rb") as handle:
            while handle.read(1 << 24):
                pass


def measure(mode: str, root: Path, names: list[str] | None, code: Path) -> dict[str, Any]:
    """One measurement (see the module docstring) in a fresh process importing the project from `code`, the
    tables read once before it."""
    warm_page_cache(root)
    command = [sys.executable, "-c", MEASURE, mode, str(root), json.dumps(names), VERSION]
    environment = {**os.environ, "PYTHONPATH": str(code)}
    done = subprocess.run(command, cwd=code, capture_output=True, text=True, check=False, env=environment)
    if done.returncode != 0:
        raise RuntimeError(f"{mode} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tables", type=Path, help="data set root to write (or reuse) the tables in")
    parser.add_argument("--scenes", type=int, default=850)
    parser.add_argument("--subsets", default="1,10", help="scene counts of the by-scene loads")
    parser.add_argument("--baseline-code", type=Path, help="a checkout whose load_dataset is the baseline")
    parser.add_argument("--out", type=Path, default=RESULTS / "loader_trainval.json")
    args = parser.parse_args()
    root = args.tables or Path(tempfile.mkdtemp(prefix="bench-loader-"))
    version_dir = root / VERSION
    counts = ensure_tables(root, args.scenes)
    print("tables:", counts, flush=True)
    names = [f"scene-{i + 1:04d}" for i in range(args.scenes)]
    runs: dict[str, Any] = {}
    if args.baseline_code is not None:
        runs["baseline_loader"] = measure("load", root, None, args.baseline_code)
    runs["whole_parse"] = measure("whole_parse", root, list(REQUIRED_TABLES), ROOT)
    runs["all_scenes"] = measure("load", root, None, ROOT)
    for count in (int(n) for n in args.subsets.split(",")):
        chosen = names[:: max(1, len(names) // count)][:count]  # spread over the file, not its first records
        runs[f"scenes_{count}"] = {"scenes": chosen, **measure("load", root, chosen, ROOT)}
    for name, run in runs.items():
        print(
            f"{name:>16}: {run['seconds']:7.1f} s, peak RSS {run['peak_rss_mb']:7.0f} MB, "
            f"anonymous {run['rss_anon_mb']:7.0f} MB, images {run['images']}",
            flush=True,
        )
    reference = runs.get("baseline_loader", runs["whole_parse"])
    sizes = {p.name: p.stat().st_size for p in sorted(version_dir.glob("*.json")) if p.name != "counts.json"}
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "tables": {"scenes": args.scenes, "records": counts, "bytes": sizes},
        "runs": runs,
        "ratios_vs": "baseline_loader" if "baseline_loader" in runs else "whole_parse",
        "seconds_ratio": {k: reference["seconds"] / max(v["seconds"], 1e-9) for k, v in runs.items()},
        "rss_anon_ratio": {
            k: reference["rss_anon_mb"] / max(v["rss_anon_mb"], 1e-9) for k, v in runs.items()
        },
    }
    atomic_write_json(args.out, results, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
