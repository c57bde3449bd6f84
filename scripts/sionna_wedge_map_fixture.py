"""First-order edge diffraction in Sionna RT's radio map around one closed box: the reference for
tests/sionna_crosscheck.rs (radio_map_diffraction_over_one_box_against_sionna_rt).

    python3 scripts/sionna_wedge_map_fixture.py tests/fixtures/sionna_wedge_map.csv

The box and materials of scripts/sionna_wedge_fixture.py (x, y in [0, 20], z in [0, 30]; marble,
metal), the transmitter at (40, 30, 20). RadioMapSolver with diffraction only (no line of sight,
reflection or refraction), max_depth 1, 10^7 samples, 3.5 GHz, isotropic V antennas; 2 m cells at
1.5 m over x in [-40, 60], y in [-40, 60]. Written: material, the cell's column and row (row 0 at
the north edge, as our rasters), its centre, and the path gain in dB (-inf where no sample
landed). Needs sionna-rt 2.2 and libLLVM 19 (scripts/sionna_env.py)."""
import csv
import sys
import tempfile

import sionna_env  # noqa: F401
import numpy as np
from sionna.rt import RadioMapSolver

from sionna_wedge_fixture import MATERIALS, box_scene

TX = (40.0, 30.0, 20.0)
X0, Y0, SIZE, CELL, Z = -40.0, -40.0, 100.0, 2.0, 1.5
SAMPLES = 10**7


def main(out_path):
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for material, thickness in MATERIALS.items():
            scene = box_scene(f"{tmp}/{material}", material, thickness, TX)
            rm = RadioMapSolver()(scene, center=[X0 + SIZE / 2, Y0 + SIZE / 2, Z],
                                  orientation=[0.0, 0.0, 0.0], size=[SIZE, SIZE],
                                  cell_size=(CELL, CELL), samples_per_tx=SAMPLES, max_depth=1,
                                  los=False, specular_reflection=False,
                                  diffuse_reflection=False, refraction=False, diffraction=True)
            pg = rm.path_gain.numpy()[0]
            centers = rm.cell_centers.numpy()
            n = pg.shape[0]
            for r in range(n):
                for c in range(pg.shape[1]):
                    x, y = centers[r, c, 0], centers[r, c, 1]
                    db = 10 * np.log10(pg[r, c]) if pg[r, c] > 0 else float("-inf")
                    # Sionna's row 0 is the southernmost; ours is the northernmost.
                    rows.append([material, c, n - 1 - r, f"{x:.3f}", f"{y:.3f}", f"{db:.4f}"])
            print(f"{material}: {np.count_nonzero(pg)} of {pg.size} cells reached")
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["material", "col", "row", "x", "y", "path_gain_db"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1])
