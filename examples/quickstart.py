# %% [markdown]
# # kodama-dag quickstart
#
# The demo twin from Python: run `graphs/demo.ron` (a synthetic city surveyed by LiDAR and 416
# street views, reconstructed into the paper's twin and scored against a drive test), read its
# radio map and Table 1, trace a few links of your own through the twin, and hand the twin to
# Sionna RT. Run it as a script from the repository root (`python examples/quickstart.py`), or
# cell by cell (`# %%` marks the cells for Jupyter and VS Code).
#
# Needs `pip install .` (the package); matplotlib for the figure (skipped with a line without
# it); sionna-rt for the last cell (skipped with a line without it). The first run takes minutes
# (BENCHMARKS.md, "the demo, cold"); later runs read the cache.
#
# `KODAMA_QUICKSTART_GRAPH` runs another graph with the same node names (CI runs the small
# `python/tests/quickstart.ron` so the check takes seconds).

# %%
import math
import os
import sys
from pathlib import Path

import numpy as np

import kodama_dag

GRAPH = os.environ.get("KODAMA_QUICKSTART_GRAPH", "graphs/demo.ron")
OUT = Path(os.environ.get("KODAMA_QUICKSTART_OUT", "out/quickstart"))
run = kodama_dag.run(GRAPH, out=OUT)
print(run)

# %% [markdown]
# ## Table 1: the twin against the drive test
#
# Each `Evaluate` node's metrics; `p2p_rmse_db` is the point-to-point RMSE, `pd_rmse_db` and
# `ci_rmse_db` the power-distance and close-in ones (README, "Table 1").

# %%
models = [r.id for r in run.records if r.kind == "Evaluate"]
print(f"{'model':<14} {'P2P RMSE':>9} {'PD RMSE':>8} {'CI RMSE':>8}  (dB)")
table = {}
for m in models:
    t = run.metrics(m)
    table[m] = t
    print(f"{m:<14} {t['p2p_rmse_db']:9.2f} {t.get('pd_rmse_db', math.nan):8.2f} "
          f"{t.get('ci_rmse_db', math.nan):8.2f}")

# %% [markdown]
# ## The radio map
#
# `coverage` is a `RadioMap` node: path gain (dB) 1.5 m above the ground, as an xarray
# DataArray in the site's CRS when xarray is installed.

# %%
coverage = run.raster("coverage", xarray=False)
gain_db, transform = coverage
finite = gain_db[np.isfinite(gain_db)]
print(f"radio map {gain_db.shape[1]} x {gain_db.shape[0]} cells of {transform[1]} m: "
      f"path gain {finite.min():.1f} to {finite.max():.1f} dB over {finite.size} cells")
try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x0, cell, _, y0, _, _ = transform
    h, w = gain_db.shape
    fig, ax = plt.subplots(figsize=(6, 5))
    im = ax.imshow(gain_db, extent=(x0, x0 + w * cell, y0 - h * cell, y0), cmap="viridis",
                   vmin=np.percentile(finite, 2), vmax=np.percentile(finite, 98))
    fig.colorbar(im, label="path gain (dB)")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set(xlabel=f"easting (m, {run.crs})", ylabel="northing (m)",
           title="the twin's radio map")
    OUT.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT / "radio_map_quickstart.png", dpi=120, bbox_inches="tight")
    print(f"figure: {OUT / 'radio_map_quickstart.png'}")
except ImportError:
    print("matplotlib is not installed: the figure is skipped", file=sys.stderr)

# %% [markdown]
# ## Your own links through the twin
#
# `trace` takes a scene file or `(run, node)`; links are (N, 6) arrays of transmitter and
# receiver positions in the site frame. Results are shaped as Sionna RT's `Paths`.

# %%
scene = (run, "twin")
# The raster transforms are in the CRS; the scene is in the site frame (CRS minus `run.origin`).
terrain, t_transform = run.raster("terrain2", xarray=False)


def ground(x, y):
    """The terrain height under site-frame (x, y): the cell's value."""
    tx0, tcell, _, ty0, _, _ = t_transform
    col = int((x + run.origin[0] - tx0) // tcell)
    row = int((ty0 - (y + run.origin[1])) // tcell)
    return float(terrain[row, col])


# A transmitter 25 m above the ground at the radio map's centre, receivers 1.5 m above it along
# a line through it.
x0, cell, _, y0, _, _ = transform
cx = x0 - run.origin[0] + gain_db.shape[1] * cell / 2
cy = y0 - run.origin[1] - gain_db.shape[0] * cell / 2
tx = np.array([cx, cy, ground(cx, cy) + 25.0])
rx = np.array([[cx + dx, cy, ground(cx + dx, cy) + 1.5] for dx in (-60.0, -30.0, 30.0, 60.0)])
links = np.column_stack([np.tile(tx, (len(rx), 1)), rx])
paths = kodama_dag.trace(scene, links, 3.5e9)
for (x, _, _), g, n in zip(rx, paths.gain_db, paths.valid.sum(axis=1)):
    print(f"rx {x - cx:+4.0f} m from the transmitter: path gain {g:7.2f} dB over {n} paths")

# %% [markdown]
# ## The twin in Sionna RT
#
# `to_sionna` hands the twin to Sionna RT in memory: one object per building and material, ITU-R
# P.2040 radio materials, the site frame's coordinates. Sionna's PathSolver then traces the links
# above with the same settings as ours (depth 3, LOS, specular reflection, refraction).
# `Run.export` writes the same scene as files: `twin.sionna` is a Mitsuba XML + PLY folder with a
# `site.json` giving its CRS and origin (load it with `merge_shapes=False` to keep one shape per
# building and material).

# %%
folder = OUT / "twin.sionna"
if not folder.exists():
    run.export("twin", folder)
print(f"Sionna RT scene: {folder / 'scene.xml'}; site: {(folder / 'site.json').read_text()}")
try:
    sionna_scene = kodama_dag.to_sionna(scene)
except ImportError as e:
    sionna_scene = None
    print(f"the twin is not handed to Sionna RT: {e}", file=sys.stderr)
if sionna_scene is not None:
    import sionna.rt as rt

    print(f"Sionna RT scene in memory: {len(sionna_scene.objects)} objects, "
          f"materials {sorted(sionna_scene.radio_materials)}")
    sionna_scene.frequency = 3.5e9
    iso = dict(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    sionna_scene.tx_array = rt.PlanarArray(**iso)
    sionna_scene.rx_array = rt.PlanarArray(**iso)
    sionna_scene.add(rt.Transmitter("tx", position=tx.tolist()))
    for i, r in enumerate(rx):
        sionna_scene.add(rt.Receiver(f"rx{i}", position=r.tolist()))
    sp = rt.PathSolver()(sionna_scene, max_depth=3, los=True, specular_reflection=True,
                         diffuse_reflection=False, refraction=True, samples_per_src=10**6, seed=1)
    re, im = (np.array(v) for v in sp.a)
    sionna_db = 10 * np.log10((re**2 + im**2).reshape(len(rx), -1).sum(axis=1))
    for (x, _, _), ours, theirs in zip(rx, paths.gain_db, sionna_db):
        print(f"rx {x - cx:+4.0f} m: kodama-dag {ours:7.2f} dB, Sionna RT {theirs:7.2f} dB")
