#!/usr/bin/env python3
"""Where site cell centres fall in latitude and longitude, computed by PROJ (through pyproj), for
the SRTM .hgt test in nodes/tests/rasters.rs.

The test writes a synthetic tile N40W075.hgt whose heights are a closed-form function of latitude
and longitude, reads it with ReadRaster into the test site (EPSG:32618, origin 583200, 4506600)
on 90 m cells, and checks the cells below against the closed form evaluated at PROJ's latitude
and longitude, so the projection the expectation rests on is not ours.

Writes tests/fixtures/hgt_reference.csv: x, y (metres in the site frame, cell centres), lat, lon.

    pip install pyproj && python3 scripts/hgt_reference.py
"""
import csv
from pathlib import Path

from pyproj import Transformer

ROOT = Path(__file__).resolve().parent.parent
ORIGIN = (583200.0, 4506600.0)
CELL = 90.0
# Cell indices east and north of the origin: the tile spans about -83 to +1.3 km east and -78 to
# +32 km north of it; corners, edges and the middle.
CELLS = [(0, 0), (-1, -1), (10, 5), (-445, -222), (-779, 280), (-900, -860), (-60, 350), (12, -700)]


def main():
    t = Transformer.from_crs("EPSG:32618", "EPSG:4326", always_xy=True)
    out = ROOT / "tests" / "fixtures" / "hgt_reference.csv"
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["x", "y", "lat", "lon"])
        for i, j in CELLS:
            x, y = i * CELL + CELL / 2, j * CELL + CELL / 2
            lon, lat = t.transform(ORIGIN[0] + x, ORIGIN[1] + y)
            w.writerow([f"{x:.1f}", f"{y:.1f}", f"{lat:.10f}", f"{lon:.10f}"])
    print(f"wrote {out}: {len(CELLS)} points")


if __name__ == "__main__":
    main()
