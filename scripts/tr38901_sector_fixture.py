"""tests/fixtures/tr38901_sector_links.csv: the 3GPP TR 38.901 UMa path loss (LOS and NLOS mixed by
the LOS probability) less the TR 38.901 sector element's gain, at every 1000th reading of the Duke
CBRS drive test, computed apart from the Rust code with numpy and pyproj. tests/tr38901_sector.rs
runs the Tr38901 stage with `tx_antenna` on the same readings and compares per link.

    python3 scripts/tr38901_sector_fixture.py ../shared/data/rf tests/fixtures/tr38901_sector_links.csv

Cells 20 m above the ground, phones 1.5 m, flat ground (graphs/duke_baselines.ron's assumptions). The cells'
azimuths are true bearings; the grid bearing is the true bearing less the meridian convergence of
UTM 17N at the cell (PROJ's `get_factors`, not the Rust side's numerical chord).
"""
import csv
import json
import sys

import numpy as np
from pyproj import Proj, Transformer

from tr38901_reference import UMA, pathloss, sector_gain_db

root, out = sys.argv[1], sys.argv[2]
STEP = 1000
ORIGIN = (687000.0, 3985000.0)  # the Duke graphs' site origin
H_BS, H_UT = 20.0, 1.5
cells = {c["pci"]: c for c in json.load(open(f"{root}/duke_cells.json"))["cells"]}
rows = list(csv.DictReader(open(f"{root}/duke_cbrs.csv")))[::STEP]
to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True)
utm = Proj("EPSG:32617")

with open(out, "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["row", "pci", "rx_x", "rx_y", "tx_grid_azimuth_deg", "uma_db", "sector_gain_db",
                "path_loss_db"])
    for i, r in enumerate(rows):
        c = cells[r["PCI"]]
        tx, ty = to_utm.transform(c["lon"], c["lat"])
        x, y = to_utm.transform(float(r["longitude"]), float(r["latitude"]))
        gamma = utm.get_factors(c["lon"], c["lat"]).meridian_convergence
        boresight = (c["azimuth_deg"] - gamma) % 360.0
        d2d = max(np.hypot(x - tx, y - ty), 1.0)
        bearing = np.degrees(np.arctan2(x - tx, y - ty))
        down = np.degrees(np.arctan2(H_BS - H_UT, d2d))
        uma = float(pathloss(d2d, c["freq_hz"] / 1e9, UMA, H_BS, H_UT))
        g = float(sector_gain_db(bearing, boresight, down))
        w.writerow([i * STEP, r["PCI"], f"{x - ORIGIN[0]:.3f}", f"{y - ORIGIN[1]:.3f}",
                    f"{boresight:.6f}", f"{uma:.6f}", f"{g:.6f}", f"{uma - g:.6f}"])
print(f"{len(rows)} links -> {out}")
