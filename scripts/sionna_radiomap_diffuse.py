"""Compares our radio map with diffuse reflection against Sionna RT's on the street canyon: every
material with scattering coefficient S = 0.5 (Lambertian), specular + diffuse to depth 2, no
refraction, 2 x 10^6 rays, 2 m cells at 1.5 m.

    kodama-dag radiomap --scene S/simple_street_canyon/simple_street_canyon.xml --tx -33,0,32 \
        --freq-hz 3.5e9 --max-depth 2 --rays 2000000 --cell-m 2 --no-transmission --diffuse \
        --scattering-coefficient 0.5 --out ours.tif
    python3 scripts/sionna_radiomap_diffuse.py S/simple_street_canyon/simple_street_canyon.xml ours.tif
"""
import sys

import sionna_env  # noqa: F401
import numpy as np
import rasterio
from sionna.rt import PlanarArray, RadioMapSolver, Transmitter, load_scene

scene = load_scene(sys.argv[1])
scene.frequency = 3.5e9
for m in scene.radio_materials.values():
    m.scattering_coefficient = 0.5
scene.tx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.rx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
scene.add(Transmitter(name="tx", position=[-33.0, 0.0, 32.0]))
rm = RadioMapSolver()(scene, cell_size=(2.0, 2.0), samples_per_tx=2 * 10**6, max_depth=2, los=True,
                      specular_reflection=True, diffuse_reflection=True, refraction=False,
                      diffraction=False)
pg = rm.path_gain.numpy()[0]
o = rasterio.open(sys.argv[2]).read(1)[::-1, :]
assert o.shape == pg.shape, (o.shape, pg.shape)
s_db = np.where(pg > 0, 10 * np.log10(np.where(pg > 0, pg, 1)), np.nan)
both = np.isfinite(s_db) & np.isfinite(o)
d = o[both] - s_db[both]
print(f"cells: sionna {np.isfinite(s_db).sum()}, ours {np.isfinite(o).sum()}, both {both.sum()}")
print(f"difference ours - sionna: median {np.median(d):+.2f} dB, |d| median {np.median(np.abs(d)):.2f} dB, "
      f"90th percentile {np.percentile(np.abs(d), 90):.2f} dB")
