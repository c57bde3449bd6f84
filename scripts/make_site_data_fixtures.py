#!/usr/bin/env python3
"""Recorded responses for scripts/site_data.py --replay (tests/site_data_recipe.py).

    python3 scripts/make_site_data_fixtures.py

Standard library only. Writes tests/fixtures/site_data/: index.json (request -> response file),
the index/search answers in the services' documented JSON/XML shapes (hand-made, not captures;
README.md there says which fields were verified where), tiny LAS 1.2 tiles, and a gzipped all-zero
SRTM 1" tile (3601 x 3601 16-bit, 25.9 MB unpacked, a few KB packed). GeoTIFF answers reuse
tests/fixtures/gdal_dem_f32.tif and gdal_ortho_rgb.tif (scripts/make_geotiff_fixtures.py); street
view images reuse nodes/tests/fixtures/mapillary/per_image/*.jpg (scripts/make_mapillary_fixtures.py).
Tile names, item ids and dates below are made up in the services' naming patterns.
"""
import gzip
import io
import json
import struct
import sys
import urllib.parse
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "tests" / "fixtures" / "site_data"
sys.dont_write_bytecode = True
sys.path.insert(0, str(ROOT / "scripts"))
import site_data as sd  # noqa: E402  (the URLs are the recipe's own, so the index matches them)


def las(path, points, cls_epsg_note=""):
    """A LAS 1.2 file, point format 0, scale 0.01, offset 0: points (x, y, z, classification)."""
    recs = b"".join(struct.pack("<iiiHBBbBH", round(x * 100), round(y * 100), round(z * 100), 100, 0x09, c, 0, 0, 0)
                    for x, y, z, c in points)
    xs, ys, zs = zip(*[(p[0], p[1], p[2]) for p in points])
    hdr = b"LASF" + struct.pack("<HH", 0, 0) + bytes(16) + bytes([1, 2])
    hdr += b"kodama-dag fixture".ljust(32, b"\0") + b"make_site_data_fixtures.py".ljust(32, b"\0")
    hdr += struct.pack("<HHHIIBHI", 1, 2026, 227, 227, 0, 0, 20, len(points))
    hdr += struct.pack("<5I", len(points), 0, 0, 0, 0)
    hdr += struct.pack("<3d", 0.01, 0.01, 0.01) + struct.pack("<3d", 0, 0, 0)
    hdr += struct.pack("<6d", max(xs), min(xs), max(ys), min(ys), max(zs), min(zs))
    assert len(hdr) == 227, len(hdr)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(hdr + recs)
    return path.stat().st_size


def gz_zeros_hgt(path):
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=0, compresslevel=9) as g:
        row = bytes(3601 * 2)
        for _ in range(3601):
            g.write(row)
    path.write_bytes(buf.getvalue())


def dump(name, doc):
    (OUT / name).write_text(json.dumps(doc, indent=1) + "\n")
    return name


def tnm_item(title, url, size, box, date, fmt):
    return {"title": title, "sourceId": "fixture-" + url.rsplit("/", 1)[-1], "publicationDate": date,
            "format": fmt, "downloadURL": url, "sizeInBytes": size,
            "boundingBox": {"minX": box[0], "maxX": box[2], "minY": box[1], "maxY": box[3]}}


def tnm(items):
    return {"total": len(items), "items": items, "errors": [], "messages": []}


def naip_item(state, year, doqq, box, epsg):
    iid = f"{state}_{doqq}_{year}0701"
    href = (f"https://naipeuwest.blob.core.windows.net/naip/v002/{state}/{year}/{state}_060cm_{year}/"
            f"{doqq[2:7]}/{doqq}_{year}0701.tif")
    return {"type": "Feature", "stac_version": "1.0.0", "id": iid, "collection": "naip", "bbox": list(box),
            "geometry": {"type": "Polygon", "coordinates": [[[box[0], box[1]], [box[2], box[1]], [box[2], box[3]],
                                                             [box[0], box[3]], [box[0], box[1]]]]},
            "properties": {"gsd": 0.6, "datetime": f"{year}-07-01T16:00:00Z", "naip:year": str(year),
                           "naip:state": state, "proj:epsg": epsg},
            "assets": {"image": {"href": href, "type": "image/tiff; application=geotiff; profile=cloud-optimized",
                                 "roles": ["data"], "title": "RGBIR COG tile"}},
            "links": []}


def mly_entity(iid, lon, lat, heading, seq):
    return {"id": iid, "computed_geometry": {"type": "Point", "coordinates": [lon, lat]},
            "geometry": {"type": "Point", "coordinates": [lon + 2e-6, lat - 1e-6]},
            "computed_altitude": 12.0, "altitude": 15.1, "computed_compass_angle": heading,
            "compass_angle": heading + 3.0, "camera_type": "perspective", "camera_parameters": [0.8, 0.0, 0.0],
            "exif_orientation": 1, "width": 24, "height": 16, "captured_at": 1714566896789, "sequence": seq,
            "quality_score": 0.8,
            "thumb_original_url": f"https://scontent-iad3-1.xx.fbcdn.net/m1/v/t6/fixture_{iid}.jpg?oh=fixture"}


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    responses = []

    def add(file, url=None, method="GET", prefix=None):
        e = {"method": method, "file": file}
        if url:
            e["url"] = url
        else:
            e["url_prefix"] = prefix
        responses.append(e)

    dem_tif, ortho_tif = "../gdal_dem_f32.tif", "../gdal_ortho_rgb.tif"
    dem_size = (OUT / dem_tif).stat().st_size
    jpg = "../../../nodes/tests/fixtures/mapillary/per_image/{}.jpg"

    # Brooklyn: NYS LAS index (layer found by name), two NYC 2017 tiles.
    bk = sd.SITES["brooklyn"]["box"]
    dump("nys_las_indexes.json", {"currentVersion": 10.81, "layers": [
        {"id": 4, "name": "NYS Southeast 4 County 2022", "parentLayerId": -1, "subLayerIds": None},
        {"id": 9, "name": "NYC TopoBathymetric 2017", "parentLayerId": -1, "subLayerIds": None},
        {"id": 10, "name": "Suffolk County 2014", "parentLayerId": -1, "subLayerIds": None}]})
    add("nys_las_indexes.json", f"{sd.NYS_LAS}?f=json")
    nyc_tiles = ["987190.las", "990190.las"]
    feats = []
    for i, name in enumerate(nyc_tiles):
        x0, y0 = int(name[:3]) * 1000, int(name[3:6]) * 1000
        las(OUT / "las" / name, [(x0 + 100, y0 + 100, 30.0, 2), (x0 + 900, y0 + 800, 180.5, 1)])
        feats.append({"attributes": {"OBJECTID": i + 1, "FILENAME": name, "COLLECTION": "NYC TopoBathymetric 2017",
                                     "DIRECT_DL": f"{sd.NYC_LAS_BASE}/{name}", "LAS_GB": 0.12}})
        add(f"las/{name}", f"{sd.NYC_LAS_BASE}/{name}")
    dump("nys_las_query_brooklyn.json", {"objectIdFieldName": "OBJECTID", "features": feats})
    add("nys_las_query_brooklyn.json", sd.NysLidar().query_url(9, bk))

    bk_dem = "https://prd-tnm.s3.amazonaws.com/StagedProducts/Elevation/1m/Projects/NY_fixture/TIFF/USGS_1M_18_x58y451_NY_fixture.tif"
    dump("tnm_dem_brooklyn.json", tnm([
        tnm_item("USGS 1 Meter 18 x58y451 NY_fixture", bk_dem, dem_size, (-74.06, 40.63, -73.93, 40.73),
                 "2020-05-01", "GeoTIFF")]))
    add("tnm_dem_brooklyn.json", sd.tnm_url("Digital Elevation Model (DEM) 1 meter", "GeoTIFF", bk))
    add(dem_tif, bk_dem)

    dump("pc_naip_brooklyn.json", {"type": "FeatureCollection", "features": [
        naip_item("ny", 2019, "m_4007360_ne_18_060", (-74.005, 40.684, -73.934, 40.754), 26918),
        naip_item("ny", 2022, "m_4007360_ne_18_060", (-74.005, 40.684, -73.934, 40.754), 26918),
        naip_item("ny", 2022, "m_4007359_nw_18_060", (-73.985, 40.684, -73.871, 40.754), 26918)]})
    responses.append({"method": "POST", "url": sd.PC_STAC, "body_contains": '"bbox": [-73.99607,',
                      "file": "pc_naip_brooklyn.json"})

    # Boulder: TNM LPC (two DRCOG tiles and one other project), 1 m DEM, NAIP 2021.
    bo = sd.SITES["boulder"]["box"]
    lpc = []
    for name, box in [("USGS_LPC_CO_DRCOG_2020_fixture_a.laz", (-105.27, 39.99, -105.262, 40.0)),
                      ("USGS_LPC_CO_DRCOG_2020_fixture_b.laz", (-105.262, 39.99, -105.25, 40.0))]:
        size = las(OUT / "las" / name, [(477400.0, 4427000.0, 1650.0, 2), (477500.0, 4427100.0, 1668.0, 6)])
        url = f"https://rockyweb.usgs.gov/vdelivery/Datasets/Staged/Elevation/LPC/Projects/CO_DRCOG_2020_fixture/LAZ/{name}"
        lpc.append(tnm_item(f"USGS Lidar Point Cloud CO_DRCOG_2020_fixture {name[:-4]}", url, size, box,
                            "2022-03-01", "LAZ"))
        add(f"las/{name}", url)
    lpc.append(tnm_item("USGS Lidar Point Cloud CO_Other_2013_fixture tile",
                        "https://rockyweb.usgs.gov/vdelivery/Datasets/Staged/Elevation/LPC/Projects/CO_Other_2013/other.laz",
                        999, (-105.3, 39.98, -105.2, 40.01), "2014-01-01", "LAS"))
    dump("tnm_lpc_boulder.json", tnm(lpc))
    add("tnm_lpc_boulder.json", sd.tnm_url("Lidar Point Cloud (LPC)", "LAS,LAZ", bo))

    bo_dem = ("https://prd-tnm.s3.amazonaws.com/StagedProducts/Elevation/1m/Projects/CO_DRCOG_2020_B20/TIFF/"
              "USGS_1M_13_x47y443_CO_DRCOG_2020_B20.tif")
    dump("tnm_dem_boulder.json", tnm([
        tnm_item("USGS 1 Meter 13 x47y443 CO_Other_2013_fixture", bo_dem.replace("CO_DRCOG_2020_B20", "CO_Other_2013"),
                 dem_size, (-105.36, 39.91, -105.24, 40.01), "2014-01-01", "GeoTIFF"),
        tnm_item("USGS 1 Meter 13 x47y443 CO_DRCOG_2020_B20", bo_dem, dem_size, (-105.36, 39.91, -105.24, 40.01),
                 "2022-03-01", "GeoTIFF"),
        tnm_item("USGS 1 Meter 13 x48y443 CO_DRCOG_2020_B20", bo_dem.replace("x47", "x48"), dem_size,
                 (-105.245, 39.91, -105.12, 40.01), "2022-03-01", "GeoTIFF")]))
    add("tnm_dem_boulder.json", sd.tnm_url("Digital Elevation Model (DEM) 1 meter", "GeoTIFF", bo))
    add(dem_tif, bo_dem)

    dump("pc_naip_boulder.json", {"type": "FeatureCollection", "features": [
        naip_item("co", 2021, "m_3910503_ne_13_060", (-105.316, 39.934, -105.247, 40.004), 26913)]})
    # One search URL for both sites: the answer is chosen by the bbox in the request body.
    responses.append({"method": "POST", "url": sd.PC_STAC, "body_contains": '"bbox": [-105.26553,',
                      "file": "pc_naip_boulder.json"})
    dump("pc_token_naip.json", {"msft:expiry": "2026-11-29T10:00:00Z",
                                "token": "st=2026-11-28T09%3A00%3A00Z&se=2026-11-29T10%3A00%3A00Z&sp=rl"
                                         "&sv=2024-05-04&sr=c&skoid=fixture&sig=FIXTURE"})
    add("pc_token_naip.json", sd.PC_TOKEN)
    for site in ("brooklyn", "boulder"):
        for f in json.loads((OUT / f"pc_naip_{site}.json").read_text())["features"]:
            responses.append({"method": "GET", "url_prefix": f["assets"]["image"]["href"] + "?st=",
                              "file": ortho_tif})

    # Every site: Overpass, SRTM/Copernicus, Mapillary.
    (OUT / "overpass.osm").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<osm version="0.6" generator="Overpass API fixture">\n'
        '<note>The data included in this document is from www.openstreetmap.org. The data is made available under ODbL.</note>\n'
        '<meta osm_base="2026-11-28T09:00:00Z"/>\n'
        '  <way id="1001">\n    <nd ref="1"/>\n    <nd ref="2"/>\n    <nd ref="3"/>\n    <nd ref="1"/>\n'
        '    <tag k="building" v="yes"/>\n    <tag k="height" v="12"/>\n  </way>\n'
        '  <node id="1" lat="0.0" lon="0.0"/>\n  <node id="2" lat="0.0001" lon="0.0"/>\n'
        '  <node id="3" lat="0.0001" lon="0.0001"/>\n'
        '</osm>\n')
    add("overpass.osm", sd.OVERPASS, "POST")
    gz_zeros_hgt(OUT / "skadi_zeros.hgt.gz")
    for t in ("N40W074", "N39W106"):
        add("skadi_zeros.hgt.gz", f"{sd.SKADI}/{t[:3]}/{t}.hgt.gz")
    add(dem_tif, sd.Copernicus().url(type("C", (), {"site": sd.SITES["painiitty"]})())[0])
    for site, ids in (("brooklyn", ["4101", "4102"]), ("boulder", ["4201", "4202"]), ("painiitty", ["4301", "4302"])):
        w, s, e, n = sd.SITES[site]["box"]
        ents = [mly_entity(iid, w + (e - w) * (k + 1) / 3, s + (n - s) / 2, 90.0 * k, f"seq{site}")
                for k, iid in enumerate(ids)]
        dump(f"mapillary_{site}.json", {"data": ents})
        add(f"mapillary_{site}.json", sd.mly_url(sd.widened(sd.SITES[site]["box"])))
        for k, ent in enumerate(ents):
            add(jpg.format(["1001", "1006"][k]), ent["thumb_original_url"])

    dump("index.json", {"responses": responses})
    total = sum(p.stat().st_size for p in OUT.rglob("*") if p.is_file())
    print(f"wrote {OUT} ({len(responses)} responses, {total} bytes)")


if __name__ == "__main__":
    main()
