"""Casts the raycast bench's munich rays with Embree (through Mitsuba 3's LLVM variant, as Sionna RT
does) and prints closest-hit rays per second: an independent reference for BENCHMARKS.md's
per-core figures on the same rays and the same CPU.

    cargo bench --bench raycast -- cast --n 1 --threads 1 --no-city --dump-rays /tmp/rays.f32
    python3 scripts/embree_rays_bench.py S/munich/munich.xml /tmp/rays.f32 [--threads 1] [--runs 5]

The rays file holds little-endian f32 rows (origin xyz, direction xyz, tmin). Mitsuba's rays have
no tmin, so each origin is moved tmin along its direction. Dr.Jit traces all rays as one wavefront
kernel (Embree's 8- or 16-wide packet calls, as the CPU allows); timed warm, best of --runs after
one run, the rays already in Dr.Jit arrays. Prints the hit count too, to compare with ours.
--rows takes a slice of the rays (the bench's first 10^6 leave the transmitter); --shuffle casts
them in a random order, which takes the coherence of consecutive rays from Embree's packets. Needs
sionna-rt 2.2 (for its scene loader) and libLLVM 19."""
import argparse
import time

import sionna_env  # noqa: F401
import drjit as dr
import mitsuba as mi
import numpy as np
from sionna.rt import load_scene

ap = argparse.ArgumentParser()
ap.add_argument("scene")
ap.add_argument("rays")
ap.add_argument("--threads", type=int, default=1)
ap.add_argument("--runs", type=int, default=5)
ap.add_argument("--rows", default=":", help="a slice of the rays, e.g. 1000000: for the bounces")
ap.add_argument("--shuffle", action="store_true",
                help="cast in a random order, so that no packet of consecutive rays is coherent")
args = ap.parse_args()
dr.set_thread_count(args.threads)

rows = np.fromfile(args.rays, dtype="<f4")
if rows.size == 0 or rows.size % 7:
    raise SystemExit(f"{args.rays}: expected rows of 7 little-endian f32 (origin, direction, tmin), "
                     f"found {rows.size} values")
rows = rows.reshape(-1, 7)
a, b = (int(v) if v else None for v in args.rows.split(":"))
rows = rows[a:b]
if args.shuffle:
    rows = rows[np.random.default_rng(1).permutation(len(rows))]
o = rows[:, 0:3] + rows[:, 3:6] * rows[:, 6:7]
d = rows[:, 3:6]
scene = load_scene(args.scene).mi_scene
ray = mi.Ray3f(mi.Point3f(*[dr.llvm.ad.Float(np.ascontiguousarray(o[:, k])) for k in range(3)]),
               mi.Vector3f(*[dr.llvm.ad.Float(np.ascontiguousarray(d[:, k])) for k in range(3)]))
dr.eval(ray)


def cast():
    si = scene.ray_intersect_preliminary(ray, coherent=False)
    hits = dr.count(si.is_valid())
    dr.eval(hits)
    return int(hits[0] if hasattr(hits, "__len__") else hits)


hits = cast()
times = []
for _ in range(args.runs):
    t = time.perf_counter()
    hits = cast()
    times.append(time.perf_counter() - t)
best = min(times)
n = len(rows)
print(f"embree (mitsuba {mi.__version__}, {mi.variant()}): {n} rays{' shuffled' if args.shuffle else ''}, {hits} hits, {args.threads} thread(s), "
      f"best {best:.3f} s = {n / best / 1e6 / args.threads:.1f} M rays/s per core "
      f"(runs {', '.join(f'{t:.3f}' for t in times)})")
