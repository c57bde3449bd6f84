#!/usr/bin/env python3
"""Compare two twins written as glTF binaries (kodama-dag's `.glb` outputs), object by object.

    python3 scripts/compare_twins.py TILED.glb UNTILED.glb

Objects are matched by class and by the centre of their bounds (within 0.5 m; a tiled run's
object names carry their tile, `x0y1/building-7`, and a tile numbers its buildings itself).
Prints per class: objects in each, matched, the largest bound difference and triangle-count
difference of the matched ones, and how many triangles each twin holds. Reads only the glTF
JSON chunk (bounds are the POSITION accessors' min/max) and the index counts.
"""
import json
import struct
import sys
from collections import defaultdict


def objects(path):
    data = open(path, "rb").read()
    if data[:4] != b"glTF":
        sys.exit(f"{path}: not a binary glTF (no 'glTF' magic)")
    length = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20 : 20 + length])
    out = []
    for node in doc["nodes"]:
        if "mesh" not in node:
            continue
        lo, hi, tris = [float("inf")] * 3, [float("-inf")] * 3, 0
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            acc = doc["accessors"][prim["attributes"]["POSITION"]]
            lo = [min(a, b) for a, b in zip(lo, acc["min"])]
            hi = [max(a, b) for a, b in zip(hi, acc["max"])]
            tris += doc["accessors"][prim["indices"]]["count"] // 3 if "indices" in prim else acc["count"] // 3
        cls = node.get("extras", {}).get("class", "?")
        out.append((cls, node.get("name", ""), lo, hi, tris))
    return out


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    a, b = objects(sys.argv[1]), objects(sys.argv[2])
    by_class = defaultdict(lambda: ([], []))
    for o in a:
        by_class[o[0]][0].append(o)
    for o in b:
        by_class[o[0]][1].append(o)
    for cls, (xs, ys) in sorted(by_class.items()):
        centre = lambda o: [(l + h) / 2 for l, h in zip(o[2], o[3])]
        free = list(ys)
        matched, worst_bound, worst_tris = 0, 0.0, 0
        for x in xs:
            cx = centre(x)
            best = min(free, key=lambda y: max(abs(p - q) for p, q in zip(cx, centre(y))), default=None)
            if best is None or max(abs(p - q) for p, q in zip(cx, centre(best))) > 0.5:
                continue
            free.remove(best)
            matched += 1
            d = max(max(abs(p - q) for p, q in zip(x[2], best[2])), max(abs(p - q) for p, q in zip(x[3], best[3])))
            worst_bound = max(worst_bound, d)
            worst_tris = max(worst_tris, abs(x[4] - best[4]))
        print(
            f"{cls:>10}: {len(xs)} / {len(ys)} objects, {matched} matched; bounds within {worst_bound:.3f} m, "
            f"triangles within {worst_tris}; triangles {sum(o[4] for o in xs)} / {sum(o[4] for o in ys)}"
        )


if __name__ == "__main__":
    main()
