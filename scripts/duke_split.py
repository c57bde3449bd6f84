"""Figures for docs/research/duke.md: the Duke CBRS readings per cell, a deterministic train /
held-out split by spatial block of the drive tracks (the CSV has no timestamps and its rows are not
in driving order, so a "track segment" is the stretch of road inside one block), how many readings
each OSM box covers and how many fall inside a building footprint, the height rasters, and the 3GPP
UMa score with one offset per cell fitted on the training half and scored on the held-out half.

    python3 scripts/duke_split.py ../shared/data [block_m] [--fixture tests/fixtures/duke_split_reference.csv]

With --fixture it also writes the reference tests/duke.rs checks graphs/duke_baselines.ron
against: 3GPP UMa and UMi, omni and with the TR 38.901 sector (65°, 8 dBi, tilt 0, at each cell's
published bearing turned to grid north; cells 20 m, phones 1.5 m), scored as Evaluate's `split`,
`windows` and `exclude_footprints` score them (see `fixture` below for the exact tests).

numpy and pyproj. The split rule, to be reimplemented in Rust bit for bit (the proposed rule is "checker"; "hash" is shown for comparison):
    bx = floor(x_utm / block_m), by = floor(y_utm / block_m)      (EPSG:32617, metres)
    checker:  held_out = (bx + by) mod 2 == 1   (Euclidean mod: 1 for odd sums, negative too)
    hash:     key = ((bx & 0xffffffff) << 32) | (by & 0xffffffff)   (u64)
              held_out = splitmix64(key ^ seed) & 1 == 1              (seed 0)
"""
import collections
import csv
import json
import sys
import xml.etree.ElementTree as ET

import numpy as np
from pyproj import Proj, Transformer

from tr38901_reference import UMA, UMI, fspl, pathloss, sector_gain_db

args = sys.argv[1:]
FIXTURE = None
if "--fixture" in args:
    k = args.index("--fixture")
    FIXTURE = args[k + 1]
    del args[k:k + 2]
root = args[0]
BLOCK = float(args[1]) if len(args) > 1 else 100.0
M64 = (1 << 64) - 1
to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True)


def splitmix64(z):
    z = (z + 0x9E3779B97F4A7C15) & M64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M64
    return z ^ (z >> 31)


def held_out(x, y, block, seed=0, rule="checker"):
    bx, by = int(np.floor(x / block)), int(np.floor(y / block))
    if rule == "checker":
        return (bx + by) % 2 == 1
    key = ((bx & 0xFFFFFFFF) << 32) | (by & 0xFFFFFFFF)
    return splitmix64(key ^ seed) & 1 == 1


cells = {c["pci"]: c for c in json.load(open(f"{root}/rf/duke_cells.json"))["cells"]}
rows = list(csv.DictReader(open(f"{root}/rf/duke_cbrs.csv")))
pci = np.array([r["PCI"] for r in rows])
lon = np.array([float(r["longitude"]) for r in rows])
lat = np.array([float(r["latitude"]) for r in rows])
rsrp = np.array([float(r["rsrp"]) for r in rows])
x, y = to_utm.transform(lon, lat)
P = sorted(set(pci))
print(f"readings {len(rows)}, unique positions {len(set(zip(lon, lat)))}; UTM extent "
      f"{x.min():.0f}..{x.max():.0f} E, {y.min():.0f}..{y.max():.0f} N")
print("per cell: n, rsrp min/median/max")
for p in P:
    k = pci == p
    print(f"  {p}: {k.sum()}  {rsrp[k].min():.0f} / {np.median(rsrp[k]):.0f} / {rsrp[k].max():.0f}")
for p in P:
    c = cells[p]
    cx, cy = to_utm.transform(c["lon"], c["lat"])
    d = np.hypot(x[pci == p] - cx, y[pci == p] - cy)
    print(f"  {p}: site UTM ({cx:.1f}, {cy:.1f}), distance median {np.median(d):.0f} m, max {d.max():.0f} m")

# --- the split ---------------------------------------------------------------------------------
def split_report(block, rule="checker"):
    test = np.array([held_out(a, b, block, rule=rule) for a, b in zip(x, y)])
    blocks = set(zip(np.floor(x / block).astype(int), np.floor(y / block).astype(int)))
    out = {p: (int((~test & (pci == p)).sum()), int((test & (pci == p)).sum())) for p in P}
    # Leakage proxy: share of held-out readings with a training reading (any cell) within 10 m.
    tr = np.stack([x[~test], y[~test]], 1)
    te = np.stack([x[test], y[test]], 1)
    g = collections.defaultdict(list)
    for i, (a, b) in enumerate(tr):
        g[(int(a // 10), int(b // 10))].append(i)
    near = 0
    for a, b in te:
        gx, gy = int(a // 10), int(b // 10)
        hit = False
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for i in g.get((gx + dx, gy + dy), ()):
                    if (tr[i, 0] - a) ** 2 + (tr[i, 1] - b) ** 2 <= 100.0:
                        hit = True
                        break
                if hit:
                    break
            if hit:
                break
        near += hit
    return test, len(blocks), out, near / max(len(te), 1)


for rule, block in [(r, b) for r in ("hash", "checker") for b in sorted({50.0, 100.0, 200.0, BLOCK})]:
    test, nb, out, leak = split_report(block, rule)
    tot = (int((~test).sum()), int(test.sum()))
    print(f"{rule} block {block:.0f} m: {nb} blocks; train/held-out {tot[0]}/{tot[1]}; "
          f"held-out readings with a training reading within 10 m: {100 * leak:.1f} %")
    print("   " + ", ".join(f"{p} {a}/{b}" for p, (a, b) in out.items()))
rng = np.random.default_rng(0)
rand = rng.random(len(rows)) < 0.5
tr = set(zip(np.round(x[~rand]).astype(int), np.round(y[~rand]).astype(int)))
print("random point split: held-out readings whose rounded position (1 m) also holds a training "
      f"reading: {100 * np.mean([(int(round(a)), int(round(b))) in tr for a, b in zip(x[rand], y[rand])]):.1f} %")
GUARD = 5.0
test, _, _, _ = split_report(BLOCK)
fx, fy = x - np.floor(x / BLOCK) * BLOCK, y - np.floor(y / BLOCK) * BLOCK
guard = (fx < GUARD) | (fx > BLOCK - GUARD) | (fy < GUARD) | (fy > BLOCK - GUARD)
train = ~test & ~guard
test = test & ~guard
print(f"proposed: checker {BLOCK:.0f} m, guard {GUARD:.0f} m: {guard.sum()} readings in the guard "
      f"band (neither half), train/held-out {train.sum()}/{test.sum()}; "
      + ", ".join(f"{p} {int((train & (pci == p)).sum())}/{int((test & (pci == p)).sum())}" for p in P))

# --- OSM boxes and footprints -------------------------------------------------------------------
def osm_footprints(path):
    t = ET.parse(path).getroot()
    b = t.find("bounds").attrib
    box = tuple(float(b[k]) for k in ("minlat", "minlon", "maxlat", "maxlon"))
    nodes = {n.get("id"): (float(n.get("lon")), float(n.get("lat"))) for n in t.iter("node")}
    ways = {w.get("id"): w for w in t.iter("way")}
    tags = lambda e: {g.get("k"): g.get("v") for g in e.findall("tag")}
    polys, hs, nb = [], [], 0
    for w in ways.values():
        tg = tags(w)
        if "building" in tg:
            nb += 1
            hs.append(("height" in tg, "building:levels" in tg))
            polys.append([nodes[n.get("ref")] for n in w.findall("nd") if n.get("ref") in nodes])
    nrel = 0
    for r in t.iter("relation"):
        tg = tags(r)
        if "building" in tg:
            nrel += 1
            hs.append(("height" in tg, "building:levels" in tg))
            for m in r.findall("member"):
                if m.get("type") == "way" and m.get("role") == "outer" and m.get("ref") in ways:
                    polys.append([nodes[n.get("ref")] for n in ways[m.get("ref")].findall("nd")
                                  if n.get("ref") in nodes])
    out = []
    for q in polys:
        if len(q) >= 3:
            a = np.array(q)
            ux, uy = to_utm.transform(a[:, 0], a[:, 1])
            out.append(np.stack([ux, uy], 1))
    return box, out, nb, nrel, hs


def inside(poly, px, py):
    xs, ys = poly[:, 0], poly[:, 1]
    res = np.zeros(len(px), bool)
    j = len(xs) - 1
    for i in range(len(xs)):
        c = ((ys[i] > py) != (ys[j] > py)) & (
            px < (xs[j] - xs[i]) * (py - ys[i]) / (ys[j] - ys[i] + 1e-300) + xs[i])
        res ^= c
        j = i
    return res


in_union = np.zeros(len(rows), bool)
in_fp = np.zeros(len(rows), bool)
for name in ("pci_ABCD", "pci_EF", "pci_EF_new"):
    box, polys, nb, nrel, hs = osm_footprints(f"{root}/duke/osm/{name}.osm")
    inb = (lat >= box[0]) & (lat <= box[2]) & (lon >= box[1]) & (lon <= box[3])
    if name != "pci_EF_new":
        in_union |= inb
    fp = np.zeros(len(rows), bool)
    for poly in polys:
        lo, hi = poly.min(0), poly.max(0)
        k = (x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])
        if k.any():
            idx = np.where(k)[0]
            fp[idx] |= inside(poly, x[idx], y[idx])
    in_fp |= fp
    wh = sum(a for a, _ in hs)
    wl = sum(b for _, b in hs)
    print(f"{name}: {nb} building ways + {nrel} relations, {len(polys)} outer rings; "
          f"with height {wh}, with levels {wl}, neither {sum(1 for a, b in hs if not a and not b)}; "
          f"readings in box {inb.sum()} ({100 * inb.mean():.1f} %), inside a footprint {fp.sum()}")
    print("   per cell in box: " + ", ".join(f"{p} {100 * inb[pci == p].mean():.0f} %" for p in P))
    for p in P:
        if p in "AE":
            c = cells[p]
            cx, cy = to_utm.transform(c["lon"], c["lat"])
            hit = any(inside(q, np.array([cx]), np.array([cy]))[0] for q in polys)
            print(f"   site of {p}{'-D' if p == 'A' else '/F'} inside a footprint: {hit}")
print(f"union of the boxes: {in_union.sum()} ({100 * in_union.mean():.1f} %); inside a footprint "
      f"{in_fp.sum()} ({100 * in_fp.mean():.1f} %)")
keep = in_union & ~in_fp
print("kept (in a box, not in a footprint), train/held-out per cell at "
      f"{BLOCK:.0f} m: " + ", ".join(
          f"{p} {int((keep & train & (pci == p)).sum())}/{int((keep & test & (pci == p)).sum())}"
          for p in P) + f"; all {int((keep & train).sum())}/{int((keep & test).sum())}")

# --- height rasters -----------------------------------------------------------------------------
for name in ("pci_EF_height_1m", "pci_EF_new_height_1m"):
    a = np.load(f"{root}/duke/heights/{name}.npy")
    nz = a[a > 0]
    print(f"{name}: {a.dtype} {a.shape}, min {a.min()}, max {a.max()}, built share "
          f"{100 * (a > 0).mean():.1f} %, median of built {np.median(nz):.1f} m")

# --- UMa with offsets fitted on the training half -----------------------------------------------
H_BS, H_UT = 20.0, 1.5


def uma(d2d, fc):
    return pathloss(d2d, fc, UMA, H_BS, H_UT)


def umi(d2d, fc):
    return pathloss(d2d, fc, UMI, H_BS, H_UT)


tx = np.array([to_utm.transform(cells[p]["lon"], cells[p]["lat"]) for p in pci])
fc = np.array([cells[p]["freq_hz"] / 1e9 for p in pci])
d2d = np.maximum(np.hypot(x - tx[:, 0], y - tx[:, 1]), 1.0)
meas = -rsrp  # path loss up to the cell's offset
# The TR 38.901 sector element (tr38901_reference.sector_gain_db: rf/antenna.rs `gain`), tilt 0,
# at each cell's published true bearing turned to a grid bearing by the meridian convergence of UTM
# 17N at its site (PROJ's `get_factors`, as scripts/tr38901_sector_fixture.py; about 1.21 deg here),
# toward the phone along the straight 3-D line between the two (the Tr38901 stage's rule: the
# unclamped plan distance, so a phone under the cell sees straight down).
utm = Proj("EPSG:32617")
grid_az = {p: (cells[p]["azimuth_deg"]
               - utm.get_factors(cells[p]["lon"], cells[p]["lat"]).meridian_convergence) % 360.0
           for p in P}
bear = np.degrees(np.arctan2(x - tx[:, 0], y - tx[:, 1]))
down = np.degrees(np.arctan2(H_BS - H_UT, np.hypot(x - tx[:, 0], y - tx[:, 1])))
sector_db = np.empty(len(rows))
for p in P:
    k = pci == p
    sector_db[k] = sector_gain_db(bear[k], grid_az[p], down[k])
print("grid bearings (published true bearing less the convergence at the site): "
      + ", ".join(f"{p} {cells[p]['azimuth_deg']:.0f} -> {grid_az[p]:.3f}" for p in P))
offs_all = {p: np.mean(meas[pci == p] - uma(d2d, fc)[pci == p]) for p in P}
print("UMa offsets fitted on all readings (graphs/duke_uma_all_readings.ron): "
      + ", ".join(f"{p} {v:.2f}" for p, v in offs_all.items()))
for label, sel in (("all readings", np.ones(len(rows), bool)), ("kept readings", keep)):
    for mname, pred in (("UMa", uma(d2d, fc)), ("UMi", umi(d2d, fc)),
                        ("FSPL", fspl(np.hypot(d2d, H_BS - H_UT), fc)),
                        ("UMa + sector", uma(d2d, fc) - sector_db),
                        ("FSPL + sector", fspl(np.hypot(d2d, H_BS - H_UT), fc) - sector_db)):
        errs, line = [], []
        for p in P:
            k = sel & (pci == p)
            off = np.mean(meas[k & train] - pred[k & train])
            e = pred[k & test] - (meas[k & test] - off)
            errs.append(e)
            line.append(f"{p} {np.sqrt(np.mean(e**2)):.2f} (offset {off:.1f})")
        e = np.concatenate(errs)
        print(f"{mname} on {label}, offsets on train, held-out P2P RMSE {np.sqrt(np.mean(e**2)):.2f} dB"
              f" (ME {np.mean(e):.2f}); " + ", ".join(line))


# --- the fixture for tests/duke.rs ---------------------------------------------------------------
# The same scoring as graphs/duke_baselines.ron's Evaluate nodes, test for test:
#  - site frame: EPSG:32617 minus the origin (687000, 3985000); the blocks use the CRS coordinates.
#  - windows: for each box file, the smallest whole-metre rectangle in the site frame holding its
#    <bounds> lat/lon box: its four corners projected, then floor of the minima and ceil of the
#    maxima. A reading is in when x_min <= x <= x_max and y_min <= y <= y_max for some window.
#    (The lat/lon box is not a rectangle in UTM, turned by the 1.21 deg meridian convergence, so
#    this keeps a few readings the lat/lon test drops; the count is printed.)
#  - footprints: ReadOsmBuildings' rule, closed ways tagged building (not "no") or building:part,
#    both files' outer rings; a reading inside one (even-odd) is left out. Counted only among the
#    readings inside a window, as Evaluate does.
#  - the split: block_m 100, guard 5, as above; offsets on the training half per cell, scores on
#    the held-out half.
#  - the models: uma_eval and umi_eval omni; uma_s_eval and umi_s_eval the same less `sector_db`
#    (the sector's gain toward each phone, above), as graphs/duke_baselines.ron's uma_s and umi_s.
ORIGIN = (687000.0, 3985000.0)
BOX_FILES = ("pci_ABCD", "pci_EF_new")


def window_of(box):
    lat0, lon0, lat1, lon1 = box
    cx, cy = to_utm.transform([lon0, lon1, lon0, lon1], [lat0, lat0, lat1, lat1])
    cx, cy = np.array(cx) - ORIGIN[0], np.array(cy) - ORIGIN[1]
    return (float(np.floor(cx.min())), float(np.floor(cy.min())),
            float(np.ceil(cx.max())), float(np.ceil(cy.max())))


def building_rings(path):
    """Outer rings (EPSG:32617) of the buildings ReadOsmBuildings reads: closed ways only (the
    files have no building relations; checked)."""
    t = ET.parse(path).getroot()
    nodes = {n.get("id"): (float(n.get("lon")), float(n.get("lat"))) for n in t.iter("node")}
    tags = lambda e: {g.get("k"): g.get("v") for g in e.findall("tag")}
    for r in t.iter("relation"):
        tg = tags(r)
        assert not (("building" in tg or "building:part" in tg)
                    and tg.get("type") in ("multipolygon", "building")), "relations not handled"
    rings = []
    for w in t.iter("way"):
        tg = tags(w)
        if not (tg.get("building", "no") != "no" or "building:part" in tg):
            continue
        refs = [n.get("ref") for n in w.findall("nd")]
        if len(refs) < 4 or refs[0] != refs[-1]:
            continue
        a = np.array([nodes[r] for r in refs])
        ux, uy = to_utm.transform(a[:, 0], a[:, 1])
        rings.append(np.stack([ux, uy], 1))
    return rings


def fixture(path):
    sx, sy = x - ORIGIN[0], y - ORIGIN[1]
    windows, rings, in_latlon = [], [], np.zeros(len(rows), bool)
    for name in BOX_FILES:
        box, _, _, _, _ = osm_footprints(f"{root}/duke/osm/{name}.osm")
        windows.append(window_of(box))
        in_latlon |= (lat >= box[0]) & (lat <= box[2]) & (lon >= box[1]) & (lon <= box[3])
        rings += building_rings(f"{root}/duke/osm/{name}.osm")
    in_win = np.zeros(len(rows), bool)
    for x0, y0, x1, y1 in windows:
        in_win |= (sx >= x0) & (sx <= x1) & (sy >= y0) & (sy <= y1)
    in_ring = np.zeros(len(rows), bool)
    for ring in rings:
        lo, hi = ring.min(0), ring.max(0)
        k = (x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])
        if k.any():
            idx = np.where(k)[0]
            in_ring[idx] |= inside(ring, x[idx], y[idx])
    kept = in_win & ~in_ring
    print("fixture windows (site metres, origin 687000, 3985000): "
          + ", ".join(f"{n} {w}" for n, w in zip(BOX_FILES, windows))
          + f"; readings in a window {in_win.sum()}, in a lat/lon box {in_latlon.sum()}, "
          f"in one and not the other {(in_win != in_latlon).sum()}")
    bx, by = np.floor(x / BLOCK), np.floor(y / BLOCK)
    fx, fy = x - bx * BLOCK, y - by * BLOCK
    guard = (fx < GUARD) | (fx > BLOCK - GUARD) | (fy < GUARD) | (fy > BLOCK - GUARD)
    odd = np.mod(bx + by, 2) == 1
    tr, te, gd = kept & ~guard & ~odd, kept & ~guard & odd, kept & guard
    out = []
    for node, pred in (("uma_eval", uma(d2d, fc)), ("umi_eval", umi(d2d, fc)),
                       ("uma_s_eval", uma(d2d, fc) - sector_db),
                       ("umi_s_eval", umi(d2d, fc) - sector_db)):
        rec = lambda k, v: out.append(f"{node},{k},{v:.6f}")
        rec("links", len(rows))
        rec("links_outside_window", (~in_win).sum())
        rec("links_in_footprint", (in_win & in_ring).sum())
        rec("links_guard", gd.sum())
        rec("links_train", tr.sum())
        rec("links_held_out", te.sum())
        errs, train_errs, no_offset = [], [], 0
        for p in P:
            c = pci == p
            if not (tr & c).any():
                no_offset += (te & c).sum()
                continue
            off = np.mean(meas[tr & c] - pred[tr & c])
            rec(f"offset_db/{p}", off)
            rec(f"offset_n/{p}", (tr & c).sum())
            e = pred[te & c] - (meas[te & c] - off)
            train_errs.append(pred[tr & c] - (meas[tr & c] - off))
            errs.append(e)
            rec(f"tx/{p}/n", len(e))
            rec(f"tx/{p}/p2p_rmse_db", np.sqrt(np.mean(e**2)))
        e = np.concatenate(errs)
        rec("links_no_offset", no_offset)
        rec("links_scored", len(e))
        rec("p2p_rmse_db", np.sqrt(np.mean(e**2)))
        rec("p2p_me_db", np.mean(e))
        rec("train/p2p_rmse_db", np.sqrt(np.mean(np.concatenate(train_errs) ** 2)))
        print(f"fixture {node}: held-out P2P RMSE {np.sqrt(np.mean(e**2)):.2f} dB over {len(e)} "
              f"readings (train {tr.sum()}, guard {gd.sum()}, outside {(~in_win).sum()}, "
              f"in a footprint {(in_win & in_ring).sum()})")
    with open(path, "w") as f:
        f.write("evaluation,metric,value\n" + "\n".join(out) + "\n")


if FIXTURE:
    fixture(FIXTURE)
