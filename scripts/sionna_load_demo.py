"""Loads the demo graph's Sionna export in Sionna RT and traces it: the proof that our Mitsuba XML +
PLY scenes are valid Sionna scenes.

    cargo run --release -- run graphs/demo.ron
    python3 scripts/sionna_load_demo.py [out/demo/scene.sionna/scene.xml]

Needs `pip install sionna-rt rasterio` and libLLVM 19 (see scripts/sionna_env.py)."""
import sys

import sionna_env  # noqa: F401  (must come before sionna.rt)
import numpy as np
import rasterio
from sionna.rt import PathSolver, PlanarArray, RadioMapSolver, Receiver, Transmitter, load_scene

path = sys.argv[1] if len(sys.argv) > 1 else "out/demo/scene.sionna/scene.xml"
scene = load_scene(path)
print(f"loaded {path}: {len(scene.objects)} objects, materials {sorted(scene.radio_materials)}")
scene.frequency = 3.5e9
scene.tx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.rx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
# A transmitter 25 m over a street of the synthetic city (y = 103 m), a receiver 1.5 m over the
# same street 80 m away. The demo site's origin is (583200, 4506600) in EPSG:32618; the terrain
# raster gives the ground height.
terrain = rasterio.open(path.replace("scene.sionna/scene.xml", "terrain.tif"))


def ground(x, y):
    row, col = terrain.index(583200.0 + x, 4506600.0 + y)
    return float(terrain.read(1)[row, col])


scene.add(Transmitter(name="tx", position=[200.0, 103.0, ground(200.0, 103.0) + 25.0]))
scene.add(Receiver(name="rx", position=[120.0, 103.0, ground(120.0, 103.0) + 1.5]))
paths = PathSolver()(scene, max_depth=3, los=True, specular_reflection=True,
                     diffuse_reflection=False, refraction=False)
a = paths.a[0].numpy() + 1j * paths.a[1].numpy()
valid = paths.valid.numpy()
print(f"paths: {int(valid.sum())} valid, path gain {10 * np.log10(np.sum(np.abs(a) ** 2)):.2f} dB")
rm = RadioMapSolver()(scene, cell_size=(5.0, 5.0), samples_per_tx=10**5, max_depth=2)
pg = rm.path_gain.numpy()[0]
print(f"radio map {pg.shape[1]} x {pg.shape[0]} cells, {np.count_nonzero(pg)} reached")
