"""An independent computation of graphs/duke_uma_all_readings.ron's scores, with numpy and pyproj: the 3GPP
TR 38.901 UMa baseline (LOS and NLOS mixed by the LOS probability, power-weighted) at every reading
of the Duke CBRS drive test, one offset per cell (measured - predicted, averaged), and the P2P
RMSE / standard deviation overall and per cell. tests/duke.rs compares the graph's metrics with
the CSV this writes.

    python3 scripts/duke_reference.py ../shared/data/rf tests/fixtures/duke_reference.csv
"""
import csv
import json
import sys

import numpy as np
from pyproj import Transformer

from tr38901_reference import UMA, pathloss

root, out = sys.argv[1], sys.argv[2]
cells = {c["pci"]: c for c in json.load(open(f"{root}/duke_cells.json"))["cells"]}
rows = list(csv.DictReader(open(f"{root}/duke_cbrs.csv")))
to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True)
H_BS, H_UT = 20.0, 1.5


def uma(d2d, fc):
    return pathloss(d2d, fc, UMA, H_BS, H_UT)


pci = np.array([r["PCI"] for r in rows])
lon = np.array([float(r["longitude"]) for r in rows])
lat = np.array([float(r["latitude"]) for r in rows])
meas = -np.array([float(r["rsrp"]) for r in rows])
x, y = to_utm.transform(lon, lat)
tx = np.array([to_utm.transform(cells[p]["lon"], cells[p]["lat"]) for p in pci])
fc = np.array([cells[p]["freq_hz"] / 1e9 for p in pci])
d2d = np.maximum(np.hypot(x - tx[:, 0], y - tx[:, 1]), 1.0)
pred = uma(d2d, fc)
err = np.empty_like(meas)
result = [("links", len(rows))]
for p in sorted(set(pci)):
    k = pci == p
    off = np.mean(meas[k] - pred[k])
    err[k] = pred[k] - (meas[k] - off)
    result += [(f"offset_db/{p}", off), (f"tx/{p}/p2p_rmse_db", np.sqrt(np.mean(err[k] ** 2)))]
rmse = np.sqrt(np.mean(err**2))
result += [("p2p_rmse_db", rmse), ("p2p_me_db", np.mean(err)),
           ("p2p_std_db", np.sqrt(max(rmse**2 - np.mean(err) ** 2, 0.0)))]
with open(out, "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["metric", "value"])
    for k, v in result:
        w.writerow([k, f"{v:.6f}"])
print("\n".join(f"{k}: {v:.4f}" for k, v in result))
