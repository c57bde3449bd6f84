#!/usr/bin/env python3
"""Writes a graph over one building footprint of N vertices (default 150,000: a 20 m outline
with 37 wobbles), for measuring the polygon paths (issue 55, class 4): the footprint extruded by
OsmBaseline, rasterized by BuildingMask and scored by FootprintScore.

    python3 scripts/large_footprint.py /tmp/large_footprint [N]
    /usr/bin/time -v kodama-dag run /tmp/large_footprint/g.ron --cache /tmp/large_footprint/cache
"""
import json
import math
import sys
from pathlib import Path

out = Path(sys.argv[1])
n = int(sys.argv[2]) if len(sys.argv) > 2 else 150_000
out.mkdir(parents=True, exist_ok=True)
ox, oy, r = 583200.0, 4506600.0, 20.0
ring = []
for i in range(n):
    t = 2 * math.pi * i / n
    s = r * (1 + 0.05 * math.sin(37 * t))
    ring.append([ox + 100 + s * math.cos(t), oy + 100 + s * math.sin(t)])
ring.append(ring[0])
doc = {
    "type": "FeatureCollection",
    "crs": {"type": "name", "properties": {"name": "EPSG:32618"}},
    "features": [
        {
            "type": "Feature",
            "id": "big",
            "properties": {"height": 12},
            "geometry": {"type": "Polygon", "coordinates": [ring]},
        }
    ],
}
(out / "fp.geojson").write_text(json.dumps(doc))
(out / "g.ron").write_text(
    """// One footprint of %d vertices through the stages that walk polygons.
Graph(
    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: 0.5),
    nodes: {
        "fp": ReadFootprints(path: "fp.geojson"),
        "t": SynthTerrain(size_m: (300.0, 300.0)),
        "osm": OsmBaseline(footprints: "fp", terrain: "t"),
        "mask": BuildingMask(above: "t", footprints: "fp"),
        "score": FootprintScore(predicted: "fp", reference: "fp"),
    },
)
"""
    % n
)
print(out / "g.ron")
