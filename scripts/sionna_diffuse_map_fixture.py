"""Sionna RT 2.2's radio map with specular and diffuse reflection on its street canyon: the
reference for nodes/tests/sionna_crosscheck.rs (radio_map_with_diffuse_reflection_against_sionna_rt).

    python3 scripts/sionna_diffuse_map_fixture.py ../shared/data/sionna-scenes \
        tests/fixtures/sionna_diffuse_map.csv

simple_street_canyon as Sionna ships it (ITU materials, its thicknesses), every material with
scattering coefficient S = 0.5 (Lambertian), the transmitter at (-33, 0, 32); RadioMapSolver with
line of sight, specular and diffuse reflection to depth 2, no refraction or diffraction, 10^7
samples, 3.5 GHz, isotropic V antennas; 2 m cells at 1.5 m over x in [-50, 50], y in [-30, 30].
Written: the cell's column and row (row 0 at the north edge, as our rasters), its centre, and the
path gain in dB (-inf where no sample landed). Needs sionna-rt 2.2 and libLLVM 19
(scripts/sionna_env.py)."""
import csv
import os
import sys

import sionna_env  # noqa: F401
import numpy as np
from sionna.rt import PlanarArray, RadioMapSolver, Transmitter, load_scene

TX = (-33.0, 0.0, 32.0)
X0, Y0, W, H, CELL, Z = -50.0, -30.0, 100.0, 60.0, 2.0, 1.5
SAMPLES = 10**7
S = 0.5


def main(scenes, out_path):
    scene = load_scene(os.path.join(scenes, "simple_street_canyon", "simple_street_canyon.xml"))
    scene.frequency = 3.5e9
    for m in scene.radio_materials.values():
        m.scattering_coefficient = S
    iso = dict(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.tx_array = PlanarArray(**iso)
    scene.rx_array = PlanarArray(**iso)
    scene.add(Transmitter(name="tx", position=list(TX)))
    rm = RadioMapSolver()(scene, center=[X0 + W / 2, Y0 + H / 2, Z], orientation=[0.0, 0.0, 0.0],
                          size=[W, H], cell_size=(CELL, CELL), samples_per_tx=SAMPLES,
                          max_depth=2, los=True, specular_reflection=True,
                          diffuse_reflection=True, refraction=False, diffraction=False, seed=1)
    pg = rm.path_gain.numpy()[0]
    centers = rm.cell_centers.numpy()
    n = pg.shape[0]
    rows = []
    for r in range(n):
        for c in range(pg.shape[1]):
            x, y = centers[r, c, 0], centers[r, c, 1]
            db = 10 * np.log10(pg[r, c]) if pg[r, c] > 0 else float("-inf")
            # Sionna's row 0 is the southernmost; ours is the northernmost.
            rows.append([c, n - 1 - r, f"{x:.3f}", f"{y:.3f}", f"{db:.4f}"])
    print(f"{np.count_nonzero(pg)} of {pg.size} cells reached")
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["col", "row", "x", "y", "path_gain_db"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
