#!/usr/bin/env python3
"""Street-view provider fixtures: tiny Mapillary API v4 downloads and Panoramax STAC items, with
the poses the readers must find, computed here independently (numpy for the rotations, pyproj for
the projection and its meridian convergence).

    pip install numpy pyproj pillow  # Pillow with WebP && python3 scripts/make_mapillary_fixtures.py

Writes nodes/tests/fixtures/mapillary/:
- per_image/<id>.json + <id>.jpg, one API v4 image entity per file:
  1001 perspective (computed_rotation, k1/k2), 1002 spherical 64 x 32 (colour quadrants by
  azimuth: red ahead, green right, blue behind, yellow left), 1003 fisheye (magenta centre),
  1004 perspective stored sideways with exif_orientation 6 (red top-left quadrant as stored),
  1005 a computed_rotation 30 degrees off its computed_compass_angle (must be dropped),
  1006 no computed_rotation (pose from computed_compass_angle, level);
- jsonl/metadata.jsonl as mapillary-downloader writes it: 2001 at 2024-05-01/seqB/2001.jpg,
  2002 found by id at other/deep/2002.webp (lossy WebP, as Mapillary serves), 2001 again (a duplicate, dropped) and the closing
  {"__complete__": true}; with the downloader's progress.json (not an entity, skipped);
- expected.json: per view id, the site-frame position (with trust_altitude, and on the terrain
  plane below plus 2.5 m), the camera-to-site rotation (rows; columns right, down, forward),
  intrinsics, size and pose source; the dropped ids.
and nodes/tests/fixtures/panoramax/: items/ (a.json perspective with pitch and roll, b.json a 360
panorama, collection/items.json an ItemCollection holding c, heading from pers:yaw, image found
by id) and expected.json likewise.

Site: EPSG:32618 (UTM 18N), origin (583200, 4506600): lon about -74.0, so true north is about
0.65 degrees west of grid north there, well above the tests' 0.01 degree tolerance.
"""
import json
import math
from pathlib import Path

import numpy as np
from PIL import Image
from pyproj import Proj, Transformer

ROOT = Path(__file__).resolve().parent.parent / "nodes" / "tests" / "fixtures"
CRS = "EPSG:32618"
ORIGIN = (583200.0, 4506600.0)
TERRAIN = {"z0": 10.0, "gx": 0.01, "gy": -0.02}  # z = z0 + gx x + gy y, site frame
CAMERA_HEIGHT = 2.5

TO_LL = Transformer.from_crs(CRS, "EPSG:4326", always_xy=True)
TO_UTM = Transformer.from_crs("EPSG:4326", CRS, always_xy=True)
UTM = Proj(CRS)


def lon_lat(x, y):
    lon, lat = TO_LL.transform(ORIGIN[0] + x, ORIGIN[1] + y)
    return round(lon, 9), round(lat, 9)


def site_xy(lon, lat):
    e, n = TO_UTM.transform(lon, lat)
    return [e - ORIGIN[0], n - ORIGIN[1]]


def enu_to_site(lon, lat):
    """Turn about z by the meridian convergence, from PROJ's analytic factors."""
    conv = UTM.get_factors(lon, lat).meridian_convergence
    # Cross-check the sign on the projected meridian: gamma is the grid bearing of true north.
    d = 1e-4
    e0, n0 = TO_UTM.transform(lon, lat - d)
    e1, n1 = TO_UTM.transform(lon, lat + d)
    gamma_fd = math.degrees(math.atan2(e1 - e0, n1 - n0))
    gamma = -conv
    assert abs(gamma - gamma_fd) < 1e-6, (gamma, gamma_fd)
    g = math.radians(gamma)
    return np.array([[math.cos(g), math.sin(g), 0], [-math.sin(g), math.cos(g), 0], [0, 0, 1.0]]), gamma


def from_angles(h, p, r):
    """Camera-to-frame rotation of heading h (clockwise from the frame's y), pitch p (up), roll r
    (clockwise seen from behind), degrees; columns right, down, forward."""
    h, p, r = map(math.radians, (h, p, r))
    fwd = np.array([math.sin(h) * math.cos(p), math.cos(h) * math.cos(p), math.sin(p)])
    right0 = np.array([math.cos(h), -math.sin(h), 0.0])
    down0 = np.cross(fwd, right0)
    right = math.cos(r) * right0 + math.sin(r) * down0
    down = -math.sin(r) * right0 + math.cos(r) * down0
    return np.column_stack([right, down, fwd])


def rodrigues(v):
    v = np.asarray(v, float)
    t = np.linalg.norm(v)
    if t < 1e-15:
        return np.eye(3)
    k = v / t
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * kx @ kx


def log_rotation(m):
    """Angle-axis of a rotation matrix, through its quaternion (robust near 180 degrees)."""
    w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
    s = math.sqrt(x * x + y * y + z * z)
    angle = 2 * math.atan2(s, w)
    v = [0.0, 0.0, 0.0] if s < 1e-15 else [angle * c / s for c in (x, y, z)]
    assert np.allclose(rodrigues(v), m, atol=1e-12)
    return v


def heading(c2f):
    return math.degrees(math.atan2(c2f[0, 2], c2f[1, 2])) % 360


def terrain_z(xy):
    return TERRAIN["z0"] + TERRAIN["gx"] * xy[0] + TERRAIN["gy"] * xy[1] + CAMERA_HEIGHT


# EXIF orientation 6: the upright image is the stored one turned 90 degrees clockwise; the upright
# camera's axes in the stored camera's frame (columns): x_up = -y, y_up = x.
EXIF6 = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1.0]])

GREY = (128, 128, 128)
QUADRANTS = [(230, 30, 30), (30, 200, 30), (30, 30, 230), (230, 220, 30)]  # ahead, right, behind, left


def blocks(w, h, fill=GREY, rect=None, colour=None):
    img = Image.new("RGB", (w, h), fill)
    if rect:
        for yy in range(rect[1], rect[3]):
            for xx in range(rect[0], rect[2]):
                img.putpixel((xx, yy), colour)
    return img


def panorama(w, h):
    img = Image.new("RGB", (w, h))
    for xx in range(w):
        lon = ((xx + 0.5) / w - 0.5) * 360.0
        q = int(((lon + 45) % 360) // 90)
        for yy in range(h):
            img.putpixel((xx, yy), QUADRANTS[q])
    return img


def fisheye(w, h):
    img = Image.new("RGB", (w, h), GREY)
    for yy in range(h):
        for xx in range(w):
            if (xx + 0.5 - w / 2) ** 2 + (yy + 0.5 - h / 2) ** 2 <= 16:
                img.putpixel((xx, yy), (220, 30, 220))
    return img


def save(img, path):
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path, quality=95, subsampling=0)


def dump(doc):
    """JSON with one view (one top-level entry) per line: small and diffable."""
    def entries(d):
        return ",\n".join(f" {json.dumps(k)}: {json.dumps(v, separators=(',', ':'))}" for k, v in d.items())
    top = [f' "views": {{\n{entries(doc["views"])}\n }}' if k == "views" else f" {json.dumps(k)}: {json.dumps(v)}"
           for k, v in doc.items()]
    return "{\n" + ",\n".join(top) + "\n}\n"


def matrix(m):
    return [[float(v) for v in row] for row in m]


def mapillary():
    out = ROOT / "mapillary"
    expected = {"site": {"crs": CRS, "origin": list(ORIGIN)}, "terrain": TERRAIN,
                "camera_height_m": CAMERA_HEIGHT, "views": {}, "dropped": {}}

    def entity(id_, xy, *, c2e_stored=None, c2e_upright=None, compass=None, camera="perspective",
               params=None, size=(24, 16), orientation=1, altitude=40.0, seq="seqA",
               captured_at=1714566896789, pose_source=None, views=None, cut=None):
        lon, lat = lon_lat(*xy)
        e = {"id": id_, "computed_geometry": {"type": "Point", "coordinates": [lon, lat]},
             "geometry": {"type": "Point", "coordinates": [lon + 2e-6, lat - 1e-6]},
             "computed_altitude": altitude, "altitude": altitude + 3.1, "camera_type": camera,
             "camera_parameters": params if params is not None else [],
             "exif_orientation": orientation, "width": size[0], "height": size[1],
             "captured_at": captured_at, "sequence": seq, "quality_score": 0.8,
             "thumb_original_url": f"https://example.invalid/{id_}.jpg"}
        if c2e_stored is not None:
            e["computed_rotation"] = log_rotation(c2e_stored.T)
        if compass is not None:
            e["computed_compass_angle"] = compass
            e["compass_angle"] = (compass + 7.0) % 360
        a, gamma = enu_to_site(lon, lat)
        sxy = site_xy(lon, lat)
        c2s = a @ c2e_upright
        iso = None
        if captured_at is not None:
            import datetime
            t = datetime.datetime.fromtimestamp(captured_at / 1000, datetime.timezone.utc)
            iso = t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{captured_at % 1000:03d}Z"
        base = {"position_trust": sxy + [altitude], "position_terrain": sxy + [terrain_z(sxy)],
                "pose_source_trust": f"{pose_source}, computed_geometry, computed_altitude (ellipsoidal)",
                "pose_source_terrain": f"{pose_source}, computed_geometry, terrain + 2.5 m",
                "captured_at": iso, "convergence_deg": gamma}
        if cut is None:
            w, h = (size[1], size[0]) if orientation in (6, 8) else size
            f = params[0] * max(size)
            expected["views"][id_] = dict(base, rotation=matrix(c2s), width=w, height=h, f=f,
                                          distortion=params[1:3] if camera == "perspective" and any(params[1:3]) else None)
        else:
            n, hfov = cut
            side = round(2 * max(size) / (2 * math.pi) * math.tan(math.radians(hfov / 2)))
            h0 = heading(c2s)
            for k in range(n):
                rk = from_angles(h0 + k * 360 / n, 0, 0)
                expected["views"][f"{id_}-{k}"] = dict(
                    base, rotation=matrix(rk), width=side, height=side,
                    f=side / 2 / math.tan(math.radians(hfov / 2)), heading_deg=(h0 + k * 360 / n) % 360,
                    centre_colour=QUADRANTS[k % 4], distortion=None)
        return e

    per = out / "per_image"
    ents = []
    c = from_angles(30, 5, 2)
    ents.append((entity("1001", (50, 50), c2e_stored=c, c2e_upright=c, compass=30.4,
                        params=[0.8, -0.05, 0.01], pose_source="computed_rotation"), blocks(24, 16, rect=(0, 0, 12, 16), colour=(40, 90, 200))))
    c = from_angles(100, 0, 0)
    ents.append((entity("1002", (70, 40), c2e_stored=c, c2e_upright=c, compass=100.0, camera="spherical",
                        size=(64, 32), pose_source="computed_rotation", cut=(4, 90.0)), panorama(64, 32)))
    c = from_angles(200, -3, 0)
    ents.append((entity("1003", (90, 60), c2e_stored=c, c2e_upright=c, compass=199.0, camera="fisheye",
                        size=(32, 24), params=[0.5, 0.02, -0.01], pose_source="computed_rotation"), fisheye(32, 24)))
    up = from_angles(280, 10, 0)
    ents.append((entity("1004", (110, 70), c2e_stored=up @ EXIF6.T, c2e_upright=up, compass=281.0,
                        params=[0.9, 0.0, 0.0], orientation=6, pose_source="computed_rotation"),
                 blocks(24, 16, rect=(0, 0, 12, 8), colour=(230, 30, 30))))
    c = from_angles(45, 0, 0)
    bad_yaw = entity("1005", (130, 80), c2e_stored=c, c2e_upright=c, compass=75.0, params=[0.8, 0, 0],
                     pose_source="computed_rotation")
    expected["views"].pop("1005")
    expected["dropped"]["1005"] = "yaw"
    ents.append((bad_yaw, blocks(24, 16)))
    ents.append((entity("1006", (150, 90), c2e_upright=from_angles(150, 0, 0), compass=150.0,
                        params=[0.8, 0, 0], pose_source="computed_compass_angle"), blocks(24, 16)))
    for e, img in ents:
        (per).mkdir(parents=True, exist_ok=True)
        (per / f"{e['id']}.json").write_text(json.dumps(e, indent=1) + "\n")
        save(img, per / f"{e['id']}.jpg")

    jl = out / "jsonl"
    c = from_angles(330, 2, -1)
    e1 = entity("2001", (40, 120), c2e_stored=c, c2e_upright=c, compass=330.0, params=[0.7, 0, 0],
                seq="seqB", pose_source="computed_rotation")
    c = from_angles(10, 0, 0)
    e2 = entity("2002", (60, 130), c2e_stored=c, c2e_upright=c, compass=10.5, params=[0.7, 0, 0],
                seq="seqB", pose_source="computed_rotation")
    expected["dropped"]["2001#2"] = "duplicate"
    jl.mkdir(parents=True, exist_ok=True)
    # As the downloader leaves a finished download: a closing marker line and its progress.json.
    (jl / "metadata.jsonl").write_text("".join(json.dumps(e) + "\n" for e in (e1, e2, e1, {"__complete__": True})))
    (jl / "progress.json").write_text(json.dumps({"original": ["2001", "2002"]}) + "\n")
    save(blocks(24, 16), jl / "2024-05-01" / "seqB" / "2001.jpg")
    blocks(24, 16, fill=(90, 90, 90)).save(jl / "other" / "deep" / "2002.webp", quality=90)
    (out / "expected.json").write_text(dump(expected))


def panoramax():
    out = ROOT / "panoramax"
    expected = {"site": {"crs": CRS, "origin": list(ORIGIN)}, "terrain": TERRAIN,
                "camera_height_m": CAMERA_HEIGHT, "views": {}}

    def item(id_, xy, alt, props, assets, h, p, r, orient, fov, size, cut=None):
        lon, lat = lon_lat(*xy)
        it = {"type": "Feature", "stac_version": "1.0.0", "id": id_,
              "geometry": {"type": "Point", "coordinates": [lon, lat, alt]},
              "properties": dict({"datetime": "2023-06-01T10:00:00+00:00",
                                  "pers:interior_orientation": {"camera_manufacturer": "Acme",
                                                                "camera_model": "X1", "focal_length": 4.2,
                                                                "field_of_view": fov,
                                                                "sensor_array_dimensions": list(size)}}, **props),
              "assets": assets, "collection": "seq-1", "links": []}
        a, gamma = enu_to_site(lon, lat)
        sxy = site_xy(lon, lat)
        c2s = a @ from_angles(h, p, r)
        base = {"position_trust": sxy + [alt], "position_terrain": sxy + [terrain_z(sxy)],
                "pose_source_trust": f"{orient}, geometry, geometry altitude (ellipsoidal)",
                "pose_source_terrain": f"{orient}, geometry, terrain + 2.5 m",
                "captured_at": "2023-06-01T10:00:00+00:00", "convergence_deg": gamma}
        if cut is None:
            f = size[0] / 2 / math.tan(math.radians(fov / 2))
            expected["views"][id_] = dict(base, rotation=matrix(c2s), width=size[0], height=size[1], f=f)
        else:
            n, hfov = cut
            side = round(2 * max(size) / (2 * math.pi) * math.tan(math.radians(hfov / 2)))
            h0 = heading(c2s)
            for k in range(n):
                expected["views"][f"{id_}-{k}"] = dict(
                    base, rotation=matrix(from_angles(h0 + k * 360 / n, 0, 0)), width=side, height=side,
                    f=side / 2 / math.tan(math.radians(hfov / 2)), heading_deg=(h0 + k * 360 / n) % 360,
                    centre_colour=QUADRANTS[k % 4])
        return it

    items = out / "items"
    url = "https://panoramax.example.invalid/api/pictures/{}/{}.jpg"
    a = item("a", (45, 55), 44.0, {"view:azimuth": 120.0, "pers:pitch": 4.0, "pers:roll": -1.0},
             {"hd": {"href": "img/a_hd.jpg", "type": "image/jpeg"}, "sd": {"href": url.format("a", "sd")}},
             120, 4, -1, "view:azimuth + pers:pitch/roll", 70.0, (24, 16))
    b = item("b", (80, 75), 45.5, {"view:azimuth": 10.0},
             {"hd": {"href": url.format("b", "hd")}, "sd": {"href": "b.jpg"}},
             10, 0, 0, "view:azimuth", 360, (64, 32), cut=(4, 90.0))
    c = item("c", (120, 95), 46.0, {"pers:yaw": 300.0},
             {"hd": {"href": url.format("c", "hd")}},
             300, 0, 0, "pers:yaw", 60.0, (20, 16))
    items.mkdir(parents=True, exist_ok=True)
    (items / "a.json").write_text(json.dumps(a, indent=1) + "\n")
    (items / "b.json").write_text(json.dumps(b, indent=1) + "\n")
    (items / "collection").mkdir(exist_ok=True)
    (items / "collection" / "items.json").write_text(
        json.dumps({"type": "FeatureCollection", "features": [c]}, indent=1) + "\n")
    save(blocks(24, 16, rect=(0, 0, 12, 16), colour=(40, 90, 200)), items / "img" / "a_hd.jpg")
    save(panorama(64, 32), items / "b.jpg")
    save(blocks(20, 16), items / "pictures" / "c.jpg")
    (out / "expected.json").write_text(dump(expected))


def main():
    mapillary()
    panoramax()
    total = sum(p.stat().st_size for d in ("mapillary", "panoramax") for p in (ROOT / d).rglob("*")
                if p.is_file())
    print(f"wrote {ROOT}/mapillary and {ROOT}/panoramax ({total} bytes)")


if __name__ == "__main__":
    main()
