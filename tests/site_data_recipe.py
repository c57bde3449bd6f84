"""scripts/site_data.py against recorded responses (tests/fixtures/site_data), no network.

    python3 -m unittest tests/site_data_recipe.py        (from the repository root)

Per site: every public file of the layout (docs/sites.md) lands at its path with the content the
replayed service gave (the tiles the index listed, the DEM the TNM answer chose, the signed NAIP
image), the Overpass query and the STAC search carry the site's boxes, SOURCES.md names every
non-public item with its holder; and: an unrecorded request fails naming its URL, --dry-run writes
nothing, a missing MAPILLARY_TOKEN skips the street views with its message, files already present
are kept, bad usage exits 2; and the live HTTP path against a server on 127.0.0.1 (retries,
resumed transfers, atomic rename). tests/site_data_recipe.rs runs this module under `cargo test`.
"""
import json
import math
import os
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "site_data.py"
FIX = ROOT / "tests" / "fixtures" / "site_data"
TOKEN = "MLY|fixture-token-not-a-real-one"

# The site boxes of /work/site-layout.md (docs/sites.md), W, S, E, N.
BOXES = {
    "brooklyn": (-73.99607, 40.69129, -73.97586, 40.69742),
    "boulder": (-105.26553, 39.99281, -105.25969, 39.99733),
    "painiitty": (24.82057, 60.22934, 24.84223, 60.24084),
}
PUBLIC = {
    "brooklyn": ["lidar/987190.las", "lidar/990190.las", "dem.tif", "ortho.tif", "osm.osm",
                 "srtm/N40W074.hgt", "mapillary/images.json", "SOURCES.md", "sources.json"],
    "boulder": ["lidar/USGS_LPC_CO_DRCOG_2020_fixture_a.laz", "lidar/USGS_LPC_CO_DRCOG_2020_fixture_b.laz",
                "dem.tif", "ortho.tif", "osm.osm", "srtm/N39W106.hgt", "mapillary/images.json",
                "SOURCES.md", "sources.json"],
    "painiitty": ["osm.osm", "dem30.tif", "mapillary/images.json", "SOURCES.md", "sources.json"],
}
# Each non-public item and (part of) its holder, as SOURCES.md must name them.
NOT_PUBLIC = {
    "brooklyn": [("measurements.csv", "Shakya et al."), ("measurements.csv", "2410.17539"),
                 ("view_outputs/", "you")],
    "boulder": [("measurements.csv", "NIST"), ("measurements.csv", "data-sharing agreement"),
                ("nist_panoramas/", "NIST"), ("view_outputs/", "you")],
    "painiitty": [("measurements.csv", "not named in the paper"), ("measurements.csv", "industry drive test"),
                  ("view_outputs/", "you")],
}


def fixture_json(name):
    return json.loads((FIX / name).read_text())


def run(*args, token=True, replay=FIX):
    env = {k: v for k, v in os.environ.items() if k != "MAPILLARY_TOKEN"}
    if token:
        env["MAPILLARY_TOKEN"] = TOKEN
    cmd = [sys.executable, str(SCRIPT), *map(str, args)]
    if replay is not None:
        cmd += ["--replay", str(replay)]
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


def log_of(path):
    return [json.loads(line) for line in Path(path).read_text().splitlines()]


def widened_ok(test, box, dbox):
    """The download box is the site box widened by 200 m (within 1 m) on every side."""
    lat = math.radians((box[1] + box[3]) / 2)
    m_lon, m_lat = 111320.0 * math.cos(lat), 111320.0
    for got, want in ((box[0] - dbox[0]) * m_lon, 200), ((box[1] - dbox[1]) * m_lat, 200), \
                     ((dbox[2] - box[2]) * m_lon, 200), ((dbox[3] - box[3]) * m_lat, 200):
        test.assertAlmostEqual(got, want, delta=1.5)


class Recipe(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.out = Path(self.tmp.name) / "data"
        self.log = Path(self.tmp.name) / "requests.jsonl"

    def tearDown(self):
        self.tmp.cleanup()

    def site(self, name, *extra, token=True):
        r = run(name, "--out", self.out, "--log", self.log, *extra, token=token)
        return r, log_of(self.log) if self.log.exists() else []

    def check_common(self, name, r, log):
        root = self.out / name
        for rel in PUBLIC[name]:
            self.assertTrue((root / rel).is_file(), f"{name}/{rel} missing\n{r.stdout}\n{r.stderr}")
        self.assertEqual((root / "osm.osm").read_bytes(), (FIX / "overpass.osm").read_bytes())
        # The Overpass query asks for buildings in the download box (S,W,N,E), as OSM XML.
        (post,) = [q for q in log if q["url"] == "https://overpass-api.de/api/interpreter"]
        self.assertEqual(post["method"], "POST")
        from urllib.parse import parse_qs
        query = parse_qs(post["body"])["data"][0]
        self.assertIn("[out:xml]", query)
        self.assertIn('way["building"]', query)
        self.assertIn("out body;", query)
        s, w, n, e = map(float, query.split('way["building"](')[1].split(")")[0].split(","))
        widened_ok(self, BOXES[name], (w, s, e, n))
        # Mapillary: the API answer's entities, each with its image beside images.json, read as
        # ReadMapillary reads a saved response ({"data": [...]}).
        want = fixture_json(f"mapillary_{name}.json")["data"]
        got = json.loads((root / "mapillary" / "images.json").read_text())["data"]
        self.assertEqual([x["id"] for x in got], [x["id"] for x in want])
        for x in got:
            self.assertTrue((root / "mapillary" / f"{x['id']}.jpg").is_file())
        (mly,) = [q for q in log if q["url"].startswith("https://graph.mapillary.com/images?")]
        from urllib.parse import urlparse, parse_qs as pq
        bbox = tuple(map(float, pq(urlparse(mly["url"]).query)["bbox"][0].split(",")))
        widened_ok(self, BOXES[name], bbox)
        self.assertNotIn("MLY|", json.dumps(log), "the token must not reach the request log")
        # SOURCES.md: every downloaded file with its sha256, every non-public item with its holder.
        md = (root / "SOURCES.md").read_text()
        for rel in PUBLIC[name]:
            if rel not in ("SOURCES.md", "sources.json"):
                self.assertIn(f"`{name}/{rel}`", md)
        for item, holder in NOT_PUBLIC[name]:
            rows = [line for line in md.splitlines() if line.startswith(f"| `{name}/{item}`")]
            self.assertTrue(any(holder in row for row in rows), f"{item}: holder {holder!r} not in {rows}")
        src = json.loads((root / "sources.json").read_text())
        import hashlib
        for f in src["files"]:
            self.assertEqual(f["sha256"], hashlib.sha256((self.out / f["path"]).read_bytes()).hexdigest())
        return root

    def check_signed_naip(self, log, fixture, year):
        (search,) = [q for q in log if q["url"] == "https://planetarycomputer.microsoft.com/api/stac/v1/search"]
        return search, json.loads(search["body"]), fixture_json(fixture), fixture_json("pc_token_naip.json")

    def test_brooklyn(self):
        r, log = self.site("brooklyn")
        self.assertEqual(r.returncode, 0, r.stderr)
        root = self.check_common("brooklyn", r, log)
        # LiDAR: the tiles the NYS index query listed, from their DIRECT_DL, as delivered.
        feats = fixture_json("nys_las_query_brooklyn.json")["features"]
        names = sorted(f["attributes"]["FILENAME"] for f in feats)
        self.assertEqual(sorted(p.name for p in (root / "lidar").iterdir()), names)
        for n in names:
            self.assertEqual((root / "lidar" / n).read_bytes(), (FIX / "las" / n).read_bytes())
        (q,) = [q for q in log if "/las_indexes/MapServer/9/query?" in q["url"]]
        self.assertIn("geometry=-73.99607%2C40.69129%2C-73.97586%2C40.69742", q["url"])
        self.assertEqual((root / "dem.tif").read_bytes(), (ROOT / "tests/fixtures/gdal_dem_f32.tif").read_bytes())
        # Ortho: the newest NAIP item containing the site box, signed with the token.
        search, body, items, token = self.check_signed_naip(log, "pc_naip_brooklyn.json", None)
        self.assertEqual(body["collections"], ["naip"])
        self.assertEqual(tuple(body["bbox"]), BOXES["brooklyn"])
        href = [f for f in items["features"] if f["id"] == "ny_m_4007360_ne_18_060_20220701"][0]["assets"]["image"]["href"]
        self.assertIn({"method": "GET", "url": href + "?" + token["token"], "body": None}, log)
        self.assertEqual((root / "ortho.tif").read_bytes(), (ROOT / "tests/fixtures/gdal_ortho_rgb.tif").read_bytes())
        hgt = (root / "srtm" / "N40W074.hgt").read_bytes()
        self.assertEqual(len(hgt), 3601 * 3601 * 2)
        self.assertFalse(any(hgt[:4096]))
        self.assertFalse(list(root.rglob("*.part")))
        self.assertIn("stand-in", (root / "SOURCES.md").read_text())

    def test_boulder(self):
        r, log = self.site("boulder")
        self.assertEqual(r.returncode, 0, r.stderr)
        root = self.check_common("boulder", r, log)
        # LiDAR: only the DRCOG tiles TNM listed (the other project's tile is never requested).
        items = fixture_json("tnm_lpc_boulder.json")["items"]
        drcog = sorted(i["downloadURL"].rsplit("/", 1)[1] for i in items if "DRCOG" in i["title"])
        self.assertEqual(sorted(p.name for p in (root / "lidar").iterdir()), drcog)
        self.assertFalse([q for q in log if "CO_Other" in q["url"]])
        tnm = [q["url"] for q in log if q["url"].startswith("https://tnmaccess.nationalmap.gov/api/v1/products?")]
        self.assertTrue(all("bbox=-105.26553%2C39.99281%2C-105.25969%2C39.99733" in u for u in tnm), tnm)
        # DEM: the DRCOG 1 m tile whose footprint contains the site box.
        self.assertTrue(any(q["url"].endswith("USGS_1M_13_x47y443_CO_DRCOG_2020_B20.tif") for q in log))
        # Ortho: NAIP 2021, signed.
        search, body, items, token = self.check_signed_naip(log, "pc_naip_boulder.json", 2021)
        self.assertEqual(tuple(body["bbox"]), BOXES["boulder"])
        self.assertTrue(body["datetime"].startswith("2021-01-01"))
        href = items["features"][0]["assets"]["image"]["href"]
        self.assertIn({"method": "GET", "url": href + "?" + token["token"], "body": None}, log)
        self.assertEqual(len((root / "srtm" / "N39W106.hgt").read_bytes()), 3601 * 3601 * 2)

    def test_painiitty(self):
        r, log = self.site("painiitty")
        # The 3D Tiles mesh has no verified endpoint: that step fails, saying what to do by hand.
        self.assertEqual(r.returncode, 1, r.stderr)
        self.assertIn("painiitty/tiles: by hand", r.stderr)
        self.assertIn("hel.fi", r.stderr)
        root = self.check_common("painiitty", r, log)
        self.assertEqual((root / "dem30.tif").read_bytes(), (ROOT / "tests/fixtures/gdal_dem_f32.tif").read_bytes())
        self.assertIn("https://copernicus-dem-30m.s3.amazonaws.com/Copernicus_DSM_COG_10_N60_00_E024_00_DEM/"
                      "Copernicus_DSM_COG_10_N60_00_E024_00_DEM.tif", [q["url"] for q in log])
        self.assertIn("Helsinki 3D reality mesh", (root / "SOURCES.md").read_text())
        # Once the user has put the converted tiles there, the same run succeeds.
        (root / "tiles").mkdir()
        (root / "tiles" / "tileset.json").write_text('{"asset": {"version": "1.0"}}\n')
        self.assertEqual(self.site("painiitty")[0].returncode, 0)

    def test_unrecorded_request_fails_naming_it(self):
        index = fixture_json("index.json")
        kept = [dict(e, file=str(FIX / e["file"])) for e in index["responses"] if "overpass" not in e.get("url", "")]
        with tempfile.TemporaryDirectory() as d:
            (Path(d) / "index.json").write_text(json.dumps({"responses": kept}))
            r = run("brooklyn", "--out", self.out, "--only", "osm,srtm", replay=d)
        self.assertEqual(r.returncode, 1)
        self.assertIn("no recorded response for POST https://overpass-api.de/api/interpreter", r.stderr)
        self.assertTrue((self.out / "brooklyn" / "srtm" / "N40W074.hgt").is_file(), "the other step still ran")
        self.assertFalse((self.out / "brooklyn" / "osm.osm").exists())

    def test_http_error_fails_naming_the_file(self):
        index = fixture_json("index.json")
        bad = "https://gisdata.ny.gov/elevation/LIDAR/NYC_TopoBathymetric2017/990190.las"
        entries = [{"method": "GET", "url": bad, "status": 404}] + \
                  [dict(e, file=str(FIX / e["file"])) for e in index["responses"]]
        with tempfile.TemporaryDirectory() as d:
            (Path(d) / "index.json").write_text(json.dumps({"responses": entries}))
            r = run("brooklyn", "--out", self.out, "--only", "lidar", replay=d)
        self.assertEqual(r.returncode, 1)
        self.assertIn(f"brooklyn/lidar: 1 of 2 files failed: {bad}: HTTP 404", r.stderr)
        self.assertTrue((self.out / "brooklyn" / "lidar" / "987190.las").is_file())
        self.assertFalse((self.out / "brooklyn" / "lidar" / "990190.las").exists())
        md = (self.out / "brooklyn" / "SOURCES.md").read_text()
        self.assertIn("990190.las: HTTP 404", md)
        self.assertIn("| `brooklyn/lidar/987190.las` |", md, "the tile that came is listed")

    def test_dry_run_writes_nothing(self):
        r = run("all", "--out", self.out, "--dry-run", replay=None)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertFalse(self.out.exists())
        for url in ("https://elevation-tiles-prod.s3.amazonaws.com/skadi/N40/N40W074.hgt.gz",
                    "https://elevation-tiles-prod.s3.amazonaws.com/skadi/N39/N39W106.hgt.gz",
                    "Copernicus_DSM_COG_10_N60_00_E024_00_DEM.tif",
                    "POST https://overpass-api.de/api/interpreter",
                    "POST https://planetarycomputer.microsoft.com/api/stac/v1/search",
                    "GET https://planetarycomputer.microsoft.com/api/sas/v1/token/naip",
                    "GET https://tnmaccess.nationalmap.gov/api/v1/products?datasets=Lidar+Point+Cloud",
                    "GET https://orthos.its.ny.gov/arcgis/rest/services/vector/las_indexes/MapServer?f=json",
                    "GET https://graph.mapillary.com/images?bbox=",
                    "brooklyn/ortho.tif", "boulder/lidar/", "painiitty/dem30.tif", "painiitty/SOURCES.md",
                    "not downloadable: boulder/measurements.csv"):
            self.assertIn(url, r.stdout)

    def test_missing_token_skips_mapillary(self):
        r, log = self.site("boulder", "--only", "mapillary", token=False)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("MAPILLARY_TOKEN is not set", r.stdout)
        self.assertIn("https://www.mapillary.com/dashboard/developers", r.stdout)
        self.assertFalse(log, "no request without a token")
        self.assertFalse((self.out / "boulder" / "mapillary").exists())
        self.assertIn("skipped", (self.out / "boulder" / "SOURCES.md").read_text())

    def test_present_files_are_kept(self):
        first, _ = self.site("brooklyn", "--only", "lidar,srtm,osm")
        self.assertEqual(first.returncode, 0, first.stderr)
        self.log.unlink()
        again, log = self.site("brooklyn", "--only", "lidar,srtm,osm")
        self.assertEqual(again.returncode, 0, again.stderr)
        self.assertIn("present", again.stdout)
        downloads = [q["url"] for q in log if q["url"].endswith((".las", ".hgt.gz"))]
        self.assertEqual(downloads, [])
        self.assertNotIn("overpass", json.dumps(log))
        # SOURCES.md keeps the records of earlier runs (--only another step).
        third, _ = self.site("brooklyn", "--only", "dem")
        self.assertEqual(third.returncode, 0, third.stderr)
        md = (self.out / "brooklyn" / "SOURCES.md").read_text()
        self.assertIn("`brooklyn/lidar/987190.las`", md)
        self.assertIn("`brooklyn/dem.tif`", md)

    def test_bad_usage_exits_2(self):
        for args in (["nowhere", "--out", self.out], ["brooklyn"], ["painiitty", "--out", self.out, "--only", "lidar"],
                     ["brooklyn", "--out", self.out, "--only", "lidar,bogus"]):
            r = run(*args, replay=None)
            self.assertEqual(r.returncode, 2, (args, r.stderr))
        self.assertFalse(self.out.exists())


class LiveDownloads(unittest.TestCase):
    """The live HTTP path (urllib) against a server on 127.0.0.1: retries, resume, atomic rename."""

    BODY = bytes(range(256)) * 64  # 16 KiB

    @classmethod
    def setUpClass(cls):
        import http.server
        import importlib.util
        import threading

        spec = importlib.util.spec_from_file_location("site_data", SCRIPT)
        cls.sd = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(cls.sd)
        cls.sd.BACKOFF_S = 0.0
        cls.seen = seen = []
        cls.plan = plan = {}
        body = cls.BODY

        class Handler(http.server.BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                seen.append((self.path, self.headers.get("Range"), self.headers.get("User-Agent")))
                todo = plan.get(self.path, [])
                how = todo.pop(0) if todo else "ok"
                if how.startswith("status"):
                    self.send_error(int(how[6:]))
                    return
                start = 0
                rng = self.headers.get("Range")
                if rng and how != "ignore-range":
                    start = int(rng.split("=")[1].rstrip("-"))
                    self.send_response(206)
                else:
                    self.send_response(200)
                self.send_header("Content-Length", str(len(body) - start))
                self.end_headers()
                if how == "truncate":
                    self.wfile.write(body[start:start + 1000])
                    self.close_connection = True
                    return
                self.wfile.write(body[start:])

        cls.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        cls.base = f"http://127.0.0.1:{cls.server.server_address[1]}"
        threading.Thread(target=cls.server.serve_forever, daemon=True).start()

    @classmethod
    def tearDownClass(cls):
        cls.server.shutdown()
        cls.server.server_close()

    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dest = Path(self.tmp.name) / "sub" / "tile.las"
        self.seen.clear()
        self.plan.clear()

    def tearDown(self):
        self.tmp.cleanup()

    def get(self, path, **kw):
        import contextlib
        import io
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            return self.sd.LiveHttp().download(self.base + path, self.dest, **kw)

    def test_retries_a_server_error_then_writes_atomically(self):
        self.plan["/a"] = ["status503", "ok"]
        self.assertEqual(self.get("/a"), "fetched")
        self.assertEqual(self.dest.read_bytes(), self.BODY)
        self.assertFalse(self.dest.with_name("tile.las.part").exists())
        self.assertEqual(len(self.seen), 2)
        self.assertIn("kodama-dag", self.seen[0][2])

    def test_a_cut_transfer_resumes_with_a_range(self):
        self.plan["/b"] = ["truncate", "ok"]
        self.get("/b")
        self.assertEqual(self.dest.read_bytes(), self.BODY)
        self.assertEqual([r for _, r, _ in self.seen], [None, "bytes=1000-"])

    def test_a_part_left_by_an_earlier_run_is_resumed(self):
        self.dest.parent.mkdir(parents=True)
        self.dest.with_name("tile.las.part").write_bytes(self.BODY[:5000])
        self.get("/c")
        self.assertEqual(self.dest.read_bytes(), self.BODY)
        self.assertEqual(self.seen[0][1], "bytes=5000-")

    def test_a_server_ignoring_the_range_starts_over(self):
        self.dest.parent.mkdir(parents=True)
        self.dest.with_name("tile.las.part").write_bytes(b"junk" * 100)
        self.plan["/d"] = ["ignore-range"]
        self.get("/d")
        self.assertEqual(self.dest.read_bytes(), self.BODY)

    def test_not_found_fails_at_once_and_writes_nothing(self):
        self.plan["/e"] = ["status404"]
        with self.assertRaises(self.sd.StepFailed) as e:
            self.get("/e")
        self.assertIn("/e: HTTP 404", str(e.exception))
        self.assertEqual(len(self.seen), 1)
        self.assertFalse(self.dest.exists())

    def test_gives_up_after_three_tries(self):
        self.plan["/f"] = ["status503"] * 5
        with self.assertRaises(self.sd.StepFailed) as e:
            self.get("/f")
        self.assertIn("tried 3 times", str(e.exception))
        self.assertEqual(len(self.seen), 3)

    def test_a_present_file_of_the_published_size_is_kept(self):
        self.dest.parent.mkdir(parents=True)
        self.dest.write_bytes(self.BODY)
        self.assertEqual(self.get("/g", expected_size=len(self.BODY)), "present")
        self.assertEqual(self.seen, [])
        self.dest.write_bytes(self.BODY[:10])  # the wrong size: fetched again
        self.assertEqual(self.get("/g", expected_size=len(self.BODY)), "fetched")
        self.assertEqual(self.dest.read_bytes(), self.BODY)


if __name__ == "__main__":
    unittest.main()
