"""The nuScenes-CAMAv2 export of a site in a data set of nuScenes v1.0-trainval's size: seconds, memory, bytes.

`cama export --format nuscenes-cama` rewrites the whole ego_pose.json (every record, the site's scenes refined,
the others as logged), writes pose_sources.json for every record and map_vectors.json for the site's samples,
and hard-links the other tables. On trainval that is 2.6 million ego_pose records, so its cost is set by the
tables, not by the site. No such data is on this machine and nothing is downloaded: the tables are
`bench/loader.py`'s (`write_tables`: 850 scenes of nuScenes' form and size, no images), written once into
`--tables` and reused.

Each measurement runs in a fresh Python process after the tables have been read once (page cache), and reports
its wall seconds and peak resident memory (`VmHWM`), as `bench/loader.py` does:
  whole_parse   `json.load` of the six tables the export reads (scene, sample, sample_data, ego_pose,
                calibrated_sensor, sensor): the floor of any export that parses them whole; the ratios' baseline
                without `--baseline-code`;
  load_site     `load_dataset(root, scenes=...)` of the site's scenes (`--site-scenes`, spread over the file),
                what `cama export` loads first;
  export_site   that load, then `export_nuscenes_cama` of a site set (a divider and a boundary along the
                scenes' common trajectory) with refined poses standing in as the logged ones moved 5 cm, into a
                fresh folder beside the tables (hard links); the bytes of the three files it writes;
  baseline_export_site  the same with another checkout's code (`--baseline-code DIR`, e.g. a `git worktree` of
                the commit before), the ratios' baseline when given.

Usage: .venv/bin/python bench/export_trainval.py [--tables DIR] [--scenes 850] [--site-scenes 10]
       [--baseline-code DIR] [--out bench/results/export_trainval.json]
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from loader import (  # bench/loader.py: this script's folder is on sys.path
    VERSION,
    ensure_tables,
    warm_page_cache,
)

from cama_pipeline.io import atomic_write_json

RESULTS = Path(__file__).parent / "results"
ROOT = Path(__file__).resolve().parents[1]
EXPORT_TABLES = ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor", "sensor")

MEASURE = """
import json, sys, time
from pathlib import Path
mode, root, names, version, out = sys.argv[1], Path(sys.argv[2]), json.loads(sys.argv[3]), sys.argv[4], Path(sys.argv[5])
started = time.perf_counter()
written = {}
if mode == "whole_parse":
    for name in names:
        with open(root / version / f"{name}.json", encoding="utf-8") as handle:
            json.load(handle)
else:
    import numpy as np
    from annotations import AnnotationSet, Georeference, MapElement
    from annotations.nuscenes_cama_format import export_nuscenes_cama
    from annotations.poses import SourcedPose
    from cama_pipeline.data import Pose, load_dataset
    dataset = load_dataset(root, check_files=False, scenes=names)
    if mode == "export_site":
        def refined(image):
            pose = image.global_from_ego
            return SourcedPose(Pose(pose.translation + np.array([0.05, 0.0, 0.0]), pose.rotation), "sfm")
        georef = Georeference(site_origin_xy=(400.0, 1170.0), origin_xy=(400.0, 1195.0), resolution=0.5,
                              width=240, height=60)
        lines = {"divider": [[10.0, 8.0], [110.0, 8.0]], "boundary": [[10.0, 4.0], [110.0, 4.0]]}
        now = "2026-12-07T00:00:00+00:00"
        elements = [MapElement.model_validate({"id": cls, "class": cls, "points_2d": points, "source": "human",
                                               "author": "bench", "created_at": now, "updated_at": now})
                    for cls, points in lines.items()]
        annotations = AnnotationSet(site_id="site-001", georeference=georef, elements=elements)
        result = export_nuscenes_cama(annotations, root, dataset, out, poses=refined)
        files = ("ego_pose.json", "pose_sources.json", "map_vectors.json")
        written = {name: (result.version_dir / name).stat().st_size for name in files}
        written = {"samples": result.samples, "vectors": result.vectors, "counts": result.counts, "bytes": written}
seconds = time.perf_counter() - started
status = {l.split(":")[0]: int(l.split()[1]) for l in open("/proc/self/status") if l.startswith(("RssAnon", "VmHWM"))}
print(json.dumps({"seconds": seconds, "peak_rss_mb": status["VmHWM"] / 1024, **written}))
"""


def measure(mode: str, root: Path, names: list[str], out: Path, code: Path = ROOT) -> dict[str, Any]:
    """One measurement (the module docstring) in a fresh process importing the project from `code`, the tables
    read once before it."""
    warm_page_cache(root)
    command = [sys.executable, "-c", MEASURE, mode, str(root), json.dumps(names), VERSION, str(out)]
    environment = {**os.environ, "PYTHONPATH": str(code)}
    done = subprocess.run(command, cwd=code, capture_output=True, text=True, check=False, env=environment)
    if done.returncode != 0:
        raise RuntimeError(f"{mode} failed:\n{done.stderr[-3000:]}")
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tables", type=Path, help="data set root to write (or reuse) the tables in")
    parser.add_argument("--scenes", type=int, default=850)
    parser.add_argument("--site-scenes", type=int, default=10, help="scenes of the exported site")
    parser.add_argument(
        "--baseline-code", type=Path, help="a checkout whose export is measured too, the baseline"
    )
    parser.add_argument("--out", type=Path, default=RESULTS / "export_trainval.json")
    args = parser.parse_args()
    root = args.tables or Path(tempfile.mkdtemp(prefix="bench-export-"))
    counts = ensure_tables(root, args.scenes)
    print("tables:", counts, flush=True)
    names = [f"scene-{i + 1:04d}" for i in range(args.scenes)]
    site = names[:: max(1, len(names) // args.site_scenes)][: args.site_scenes]
    with tempfile.TemporaryDirectory(dir=root.parent, prefix=".bench-export-out-") as scratch:
        runs = {
            "whole_parse": measure("whole_parse", root, list(EXPORT_TABLES), Path(scratch) / "unused"),
            "load_site": measure("load_site", root, site, Path(scratch) / "unused"),
            "export_site": measure("export_site", root, site, Path(scratch) / "export"),
        }
        if args.baseline_code is not None:
            runs["baseline_export_site"] = measure(
                "export_site", root, site, Path(scratch) / "baseline", args.baseline_code
            )
    for name, run in runs.items():
        print(f"{name:>12}: {run['seconds']:7.1f} s, peak RSS {run['peak_rss_mb']:7.0f} MB", flush=True)
    reference = "baseline_export_site" if "baseline_export_site" in runs else "whole_parse"
    baseline = runs[reference]
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "machine": {
            "platform": platform.platform(),
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
        },
        "tables": {"scenes": args.scenes, "records": counts},
        "site_scenes": site,
        "runs": runs,
        "ratios_vs": reference,
        "seconds_ratio": {k: v["seconds"] / baseline["seconds"] for k, v in runs.items()},
        "peak_rss_ratio": {k: v["peak_rss_mb"] / baseline["peak_rss_mb"] for k, v in runs.items()},
    }
    atomic_write_json(args.out, results, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
