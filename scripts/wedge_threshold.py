"""How much the edges that barely bend (terrain facets, domes, tessellated curves) add to traced
links, and what they cost: the measurement behind `min_wedge_deg`'s default (issue 54).

    python3 scripts/wedge_threshold.py out/demo/scene.sionna target/release/kodama-dag [--set dev|test]

The scene is a twin exported for Sionna (`scene.sionna`, terrain included). Receivers stand 1.5 m
above the terrain mesh at random points outside every building's bounding box; the transmitter
25 m above the terrain. Two fixed sets: `dev` (seed 1, the transmitter at (200, 103)) to choose
the threshold on, `test` (seed 2, the transmitter at (110, 210)) to report it on. Each set is
traced at depth 3 with diffraction, 200,000 rays (the demo's Trace), at each threshold; printed:
the wall time, and |gain - gain at 0 degrees| over the links both reach (median, 90th percentile,
largest) with the links reached at one threshold only.

    python3 scripts/wedge_threshold.py out/demo/scene.sionna target/release/kodama-dag --within-shapes

traces each set twice at threshold 0 instead: with our wedges, and with only the wedges Sionna RT
finds (`--wedges-within-shapes`: both faces in one shape, where the export splits a building by
material): what a Sionna trace of the export loses to that split."""
import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

import numpy as np

THRESHOLDS = [0.0, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0]
SETS = {"dev": (1, (200.0, 103.0)), "test": (2, (110.0, 210.0))}
LINKS = 200


def ply_vertices(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    head = data[:end].decode()
    n = int(re.search(r"element vertex (\d+)", head).group(1))
    return np.frombuffer(data[end:end + 12 * n], dtype="<f4").reshape(-1, 3).astype(float)


def scene_meshes(scene_dir):
    root = ET.parse(os.path.join(scene_dir, "scene.xml")).getroot()
    out = []
    for shape in root.iter("shape"):
        name = shape.get("id", "")
        fn = next(s.get("value") for s in shape.iter("string") if s.get("name") == "filename")
        out.append((name, ply_vertices(os.path.join(scene_dir, fn))))
    return out


def link_set(scene_dir, which):
    seed, (tx_x, tx_y) = SETS[which]
    meshes = scene_meshes(scene_dir)
    terrain = np.concatenate([v for n, v in meshes if "terrain" in n])
    boxes = [(v[:, 0].min(), v[:, 0].max(), v[:, 1].min(), v[:, 1].max())
             for n, v in meshes if "terrain" not in n]

    def ground(x, y):
        i = np.argmin((terrain[:, 0] - x) ** 2 + (terrain[:, 1] - y) ** 2)
        return terrain[i, 2]

    def outdoors(x, y):
        return not any(a - 1 <= x <= b + 1 and c - 1 <= y <= d + 1 for a, b, c, d in boxes)

    lo, hi = terrain[:, :2].min(0) + 5, terrain[:, :2].max(0) - 5
    rng = np.random.default_rng(seed)
    tx = (tx_x, tx_y, ground(tx_x, tx_y) + 25.0)
    links = []
    while len(links) < LINKS:
        x, y = rng.uniform(lo, hi)
        if outdoors(x, y):
            links.append((*tx, x, y, ground(x, y) + 1.5))
    return links


def trace(binary, scene_dir, links_csv, threshold, out, extra=()):
    cmd = [binary, "trace", "--scene", os.path.join(scene_dir, "scene.xml"), "--links", links_csv,
           "--freq-hz", "3.5e9", "--max-depth", "3", "--rays", "200000", "--diffraction",
           "--min-wedge-deg", str(threshold), "--out", out, *extra]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    took = time.perf_counter() - start
    with open(out) as f:
        gains = [float(r["path_gain_db"]) for r in csv.DictReader(f)]
    return took, np.array(gains)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scene_dir")
    ap.add_argument("binary")
    ap.add_argument("--set", choices=sorted(SETS), default="dev")
    ap.add_argument("--within-shapes", action="store_true",
                    help="compare our wedges with Sionna's (both faces in one shape)")
    args = ap.parse_args()
    links = link_set(args.scene_dir, args.set)
    with tempfile.TemporaryDirectory() as tmp:
        links_csv = os.path.join(tmp, "links.csv")
        with open(links_csv, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["tx_x", "tx_y", "tx_z", "rx_x", "rx_y", "rx_z"])
            w.writerows(links)
        base = None
        print(f"{args.set} set: {len(links)} links")
        runs = [(t, ()) for t in THRESHOLDS]
        if args.within_shapes:
            runs = [(0.0, ()), (0.0, ("--wedges-within-shapes",))]
        for t, extra in runs:
            took, gains = trace(args.binary, args.scene_dir, links_csv, t,
                                os.path.join(tmp, f"out{t}{len(extra)}.csv"), extra)
            if base is None:
                base = gains
            both = np.isfinite(base) & np.isfinite(gains)
            d = np.abs(gains[both] - base[both])
            one = int(np.count_nonzero(np.isfinite(base) != np.isfinite(gains)))
            print(f"min_wedge_deg {t:5.1f}{' within shapes' if extra else ''}: {took:7.2f} s; "
                  f"|gain - gain at 0| median "
                  f"{np.median(d):.3f} dB, 90th percentile {np.percentile(d, 90):.3f} dB, "
                  f"largest {d.max():.3f} dB over {both.sum()} links; {one} reached on one side")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
