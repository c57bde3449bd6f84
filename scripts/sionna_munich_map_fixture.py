"""Sionna RT 2.2's radio map of munich at the paper's settings (12 interactions; LOS, specular and
diffuse reflection, refraction, diffraction): the reference for nodes/tests/sionna_crosscheck.rs
(radio_map_at_depth_twelve_against_sionna_rt).

    python3 scripts/sionna_munich_map_fixture.py ../shared/data/sionna-scenes \
        tests/fixtures/sionna_munich_map_d12.csv

munich as Sionna ships it, every material with scattering coefficient S = 0.3 (Lambertian), the
transmitter at (8.5, 21, 27), 3.5 GHz, isotropic V antennas; RadioMapSolver's default plane (the
scene's extent) with 5 m cells at 1.5 m. A map this deep is a Monte Carlo estimate whose far
cells are reached by a few rare paths: two runs of Sionna itself (10^7 and 10^8 samples) differ
there by a median 2.9 dB and a 90th percentile of 16 dB. So the fixture keeps the cells where
Sionna has converged, those whose two runs agree within 1 dB, with the 10^8 run's path gain.
Written: the cell's column and row (row 0 at the north edge, as our rasters), its centre, and the
path gain in dB. Needs sionna-rt 2.2 and libLLVM 19 (scripts/sionna_env.py)."""
import csv
import os
import sys

import sionna_env  # noqa: F401
import numpy as np
from sionna.rt import PlanarArray, RadioMapSolver, Transmitter, load_scene

TX = (8.5, 21.0, 27.0)
S = 0.3
DEPTH = 12
CONVERGED_DB = 1.0


def radio_map(path, samples):
    scene = load_scene(path)
    scene.frequency = 3.5e9
    for m in scene.radio_materials.values():
        m.scattering_coefficient = S
    iso = dict(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.tx_array = PlanarArray(**iso)
    scene.rx_array = PlanarArray(**iso)
    scene.add(Transmitter(name="tx", position=list(TX)))
    rm = RadioMapSolver()(scene, cell_size=(5.0, 5.0), samples_per_tx=samples, max_depth=DEPTH,
                          los=True, specular_reflection=True, diffuse_reflection=True,
                          refraction=True, diffraction=True, seed=1)
    pg = rm.path_gain.numpy()[0]
    with np.errstate(divide="ignore"):
        return np.where(pg > 0, 10 * np.log10(pg), -np.inf), rm.cell_centers.numpy()


def main(scenes, out_path):
    path = os.path.join(scenes, "munich", "munich.xml")
    coarse, _ = radio_map(path, 10**7)
    fine, centers = radio_map(path, 10**8)
    n = fine.shape[0]
    rows = []
    for r in range(n):
        for c in range(fine.shape[1]):
            a, b = coarse[r, c], fine[r, c]
            if np.isfinite(a) and np.isfinite(b) and abs(a - b) < CONVERGED_DB:
                x, y = centers[r, c, 0], centers[r, c, 1]
                # Sionna's row 0 is the southernmost; ours is the northernmost.
                rows.append([c, n - 1 - r, f"{x:.3f}", f"{y:.3f}", f"{b:.4f}"])
    print(f"{np.isfinite(fine).sum()} cells reached at 10^8 samples; {len(rows)} converged "
          f"(10^7 and 10^8 within {CONVERGED_DB} dB) of {fine.size}")
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["col", "row", "x", "y", "path_gain_db"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
