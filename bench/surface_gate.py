"""The surface's SfM gate: which SfM road points join the elevation fit, on sites whose road grade changes or not.

The elevation MLP is fitted first to the strip under the keyframes; beyond the strip its curvature prior continues
it like a plane. SfM road points within `sfm_gate_m` of that fit then join it (`cama_pipeline.surface.fit`), and
with `sfm_gate_rounds` > 1 they are gated again against each new fit while the inliers grow. Where the grade
changes past the ends of the drives (a hill that flattens), the points there lie further than a tight gate from the
plane and never correct it. Each variant below runs the surface stage with the site's SfM poses, as the product
does (`bench/surface.py`'s `run_source`: a fresh workspace sharing the site's sites, SfM and masks), all in one run
per site (`bench/surface_variants.py`'s loop), and is scored as `bench/surface.py` scores a run: the road's
elevation RMSE (and by distance from the trajectory), the class IoU against the truth in the world's frame and in the reconstruction's own, PSNR, seconds.

Usage: .venv/bin/python bench/surface_gate.py --site SITE [--site SITE ...] [--variant NAME=GATE_M,ROUNDS ...]
       [--threads 2] [--out bench/results/surface_gate.json]
The first variant is the baseline the others are compared with (default: the shipped `SurfaceConfig`'s gate).
"""

from dataclasses import replace
from pathlib import Path

from cama_pipeline.surface import SurfaceConfig

RESULTS = Path(__file__).parent / "results"
DEFAULT_VARIANTS = (
    "gate 0.1 m=0.1,1",
    "gate 0.5 m=0.5,1",
    "gate 0.5 m, 4 rounds=0.5,4",
    "gate 1 m, 4 rounds=1.0,4",
)


def parse_variant(text: str) -> tuple[str, float, int]:
    """`NAME=GATE_M,ROUNDS` -> (name, gate in metres, rounds); SystemExit naming the text when malformed."""
    name, _, values = text.rpartition("=")
    try:
        gate_text, rounds_text = values.split(",")
        gate_m, rounds = float(gate_text), int(rounds_text)
    except ValueError:
        raise SystemExit(f"--variant {text!r}: expected NAME=GATE_M,ROUNDS, e.g. 'wide=0.5,4'") from None
    if not name or gate_m <= 0 or rounds < 1:
        raise SystemExit(f"--variant {text!r}: a name, a gate > 0 and rounds >= 1 are needed")
    return name, gate_m, rounds


def main() -> None:
    # bench/surface_variants.py, on sys.path when this runs as a script (tests import the rest)
    from surface_variants import parse_arguments, run_variants, write_results

    args = parse_arguments(__doc__.splitlines()[0], "NAME=GATE_M,ROUNDS", RESULTS / "surface_gate.json")
    base = SurfaceConfig(torch_threads=args.threads)
    variants = [
        (
            name,
            replace(base, sfm_gate_m=gate_m, sfm_gate_rounds=rounds),
            {"sfm_gate_m": gate_m, "sfm_gate_rounds": rounds},
        )
        for name, gate_m, rounds in (parse_variant(text) for text in (args.variant or DEFAULT_VARIANTS))
    ]
    write_results(args.out, run_variants(args.site, variants), args.threads)


if __name__ == "__main__":
    main()
