"""Times Sionna RT's radio map of munich (the BENCHMARKS.md case) and compares it with ours.

    kodama-dag radiomap --scene S/munich/munich.xml --tx 8.5,21,27 --freq-hz 3.5e9 --max-depth 3 \
        --rays 1000000 --cell-m 5 --height-m 1.5 --no-diffraction --out ours.tif
    python3 scripts/sionna_radiomap_bench.py S/munich/munich.xml ours.tif [--rays N] [--depth D] [--runs R] \
        [--diffraction]

Sionna: RadioMapSolver, 10^6 rays (--rays), depth 3 (--depth), 5 m cells at 1.5 m, LOS + specular + refraction, no
diffuse (--diffuse S: Lambertian diffuse reflection with scattering coefficient S on every
material; run ours with --diffuse --scattering-coefficient S), no diffraction (--diffraction:
first-order edge diffraction; run ours with --diffraction too), isotropic V antennas; timed warm (best of --runs, default 3, after one run). The maps are
compared cell by cell in dB where both are reached; `-` for ours times Sionna alone. --threads N
limits Dr.Jit's LLVM backend to N threads (thread scaling); KODAMA_MI_VARIANT=cuda_ad_mono_polarized
runs it on the GPU. Needs sionna-rt 2.2, rasterio (for the comparison), libLLVM 19."""
import argparse
import time

import sionna_env  # noqa: F401
import drjit as dr
import numpy as np
from sionna.rt import PlanarArray, RadioMapSolver, Transmitter, load_scene

ap = argparse.ArgumentParser()
ap.add_argument("scene")
ap.add_argument("ours")
ap.add_argument("--rays", type=float, default=1e6)
ap.add_argument("--depth", type=int, default=3)
ap.add_argument("--runs", type=int, default=3)
ap.add_argument("--diffraction", action="store_true")
ap.add_argument("--diffuse", type=float, default=0.0, metavar="S",
                help="diffuse reflection too, every material's scattering coefficient S")
ap.add_argument("--threads", type=int, default=0)
args = ap.parse_args()
if args.threads > 0:
    dr.set_thread_count(args.threads)

scene = load_scene(args.scene)
scene.frequency = 3.5e9
if args.diffuse > 0:
    for m in scene.radio_materials.values():
        m.scattering_coefficient = args.diffuse
scene.tx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.rx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.add(Transmitter(name="tx", position=[8.5, 21.0, 27.0]))
solver = RadioMapSolver()
kw = dict(cell_size=(5.0, 5.0), samples_per_tx=int(args.rays), max_depth=args.depth, los=True,
          specular_reflection=True, diffuse_reflection=args.diffuse > 0, refraction=True,
          diffraction=args.diffraction)
rm = solver(scene, **kw)
times = []
for _ in range(args.runs):
    t = time.perf_counter()
    rm = solver(scene, **kw)
    pg = rm.path_gain.numpy()[0]  # forces evaluation
    times.append(time.perf_counter() - t)
centers = rm.cell_centers.numpy()
print(f"sionna: {int(args.rays)} rays, depth {args.depth}, {pg.shape[1]} x {pg.shape[0]} cells, warm {min(times):.3f} s (runs {', '.join(f'{t:.3f}' for t in times)}), "
      f"{np.count_nonzero(pg)} cells reached, {dr.thread_count()} threads")
if args.ours == "-":
    raise SystemExit(0)
import rasterio  # noqa: E402


ours = rasterio.open(args.ours)
o = ours.read(1)
# Sionna's row 0 is the southernmost (y grows with the row); GeoTIFF row 0 is north.
o = o[::-1, :]
t = ours.transform
x0, y_top = t.c, t.f
ny, nx = o.shape
ox = x0 + (np.arange(nx) + 0.5) * t.a
oy = y_top - (ny - 0.5 - np.arange(ny)) * (-t.e)
assert o.shape == pg.shape, (o.shape, pg.shape)
dx = np.abs(ox - centers[0, :, 0]).max()
dy = np.abs(oy - centers[:, 0, 1]).max()
print(f"cell centres agree to {max(dx, dy):.3g} m")
s_db = np.where(pg > 0, 10 * np.log10(np.where(pg > 0, pg, 1)), np.nan)
both = np.isfinite(s_db) & np.isfinite(o)
only_s = np.isfinite(s_db) & ~np.isfinite(o)
only_o = ~np.isfinite(s_db) & np.isfinite(o)
d = np.abs(o[both] - s_db[both])
print(f"cells reached: sionna {np.isfinite(s_db).sum()}, ours {np.isfinite(o).sum()}, both {both.sum()}, "
      f"sionna only {only_s.sum()}, ours only {only_o.sum()}")
print(f"|difference| over cells reached by both: median {np.median(d):.2f} dB, 90th percentile {np.percentile(d, 90):.2f} dB, "
      f"mean difference {np.mean(o[both] - s_db[both]):+.2f} dB")
# Cells reached by many rays are where Monte Carlo noise is low: the well-lit 10 % of cells.
strong = both & (s_db > np.nanpercentile(s_db[both], 90))
ds = np.abs(o[strong] - s_db[strong])
print(f"strongest 10 % of those cells: median {np.median(ds):.2f} dB, 90th percentile {np.percentile(ds, 90):.2f} dB")
