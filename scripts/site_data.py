#!/usr/bin/env python3
"""Download the public inputs of the paper's three sites into the layout graphs/<site>.ron reads.

    python3 scripts/site_data.py SITE --out DATA [--only STEP,...] [--dry-run] [--replay DIR]

SITE is brooklyn, boulder, painiitty or all. Files land under DATA/<site>/ (docs/sites.md gives
the layout, the sources and what is not public). Standard library only; no GDAL.

Steps (--only takes a comma-separated list; a site runs those it has):
  lidar      brooklyn: NYC 2017 Topobathymetric LiDAR tiles (.las, EPSG:2263, US feet) listed by the
             NYS GIS LAS tile index (orthos.its.ny.gov, ArcGIS MapServer "vector/las_indexes"),
             fetched from gisdata.ny.gov. The index layer is found by its name (NYC + 2017); the
             layer number and the FILENAME / DIRECT_DL fields were seen in third-party code only,
             not in NYS documentation: if the layer is not found the step fails and names the
             layers it saw (pass --nys-las-layer ID).
             boulder: USGS 3DEP "Lidar Point Cloud (LPC)" tiles of the DRCOG project covering the
             site, listed by the TNM Access API (tnmaccess.nationalmap.gov/api/v1/products).
  dem        brooklyn, boulder: the USGS 3DEP 1 m DEM tile (TNM Access API, "Digital Elevation Model
             (DEM) 1 meter") whose footprint contains the site box -> dem.tif. For Brooklyn this is
             the public stand-in for the NYC 2017 bare-earth DEM the paper used (no verified
             download URL for that one; docs/sites.md says how to get it by hand).
  ortho      brooklyn, boulder: the NAIP quarter-quad containing the site, from the Microsoft
             Planetary Computer STAC API (collection "naip"; Boulder year 2021 as in the paper,
             Brooklyn the newest year), signed through its SAS token API -> ortho.tif. For Brooklyn
             NAIP stands in for the NYS 2024 orthophoto the paper used (by hand, docs/sites.md).
  osm        all sites: OpenStreetMap buildings in the download box (site box + 200 m) from the
             Overpass API as OSM XML -> osm.osm.
  srtm       brooklyn, boulder: SRTM 1-arc-second tile(s) from the AWS Terrain Tiles "skadi" set
             (3601 x 3601 .hgt, gunzipped) -> srtm/<tile>.hgt.
  dem30      painiitty: Copernicus GLO-30 DEM tile N60 E024 from the AWS open data bucket -> dem30.tif.
  mapillary  all sites: Mapillary API v4 image entities in the download box plus each image
             (thumb_original_url) -> mapillary/images.json and mapillary/<id>.jpg, the layout
             ReadMapillary reads. Needs MAPILLARY_TOKEN in the environment (never on the command
             line: arguments are visible to every user through ps and stay in shell history).
             Without it the step is skipped with a line saying how to get a token.
  tiles      painiitty: the Helsinki 3D reality mesh (2017) as OGC 3D Tiles. No endpoint could be
             verified (the city publishes OBJ and 3MX): the step fails and says what to do by hand,
             until tiles/tileset.json is there.

Not downloadable (listed in <site>/SOURCES.md with their holders): the measurements of every site,
NIST's panoramas (Boulder) and view_outputs/ (your own models' outputs).

Downloads go to <file>.part and are renamed when complete; a .part left by an interrupted run is
resumed (HTTP Range); a file already present (with the published size, where one is published) is
kept. Each request is tried 3 times (network errors, HTTP 429 and 5xx). Every site folder gets
SOURCES.md and sources.json: what came from where, when, its licence, size and sha256.

Endpoints, parameters and answer fields were checked against public documentation and public
client code, not by calling the services from this repository (docs/sites.md says which pieces are
unverified). Where a piece could not be checked the step says so when it fails.

--dry-run prints the requests and files without sending or writing anything (requests that depend
on an index response are shown as patterns). --replay DIR answers every request from DIR/index.json
({"responses": [{"method", "url" | "url_prefix" | "url_pattern", optional "body_contains", "file",
optional "status"}]}, files relative to DIR; the first entry that matches answers); a request with
no recorded response is an error naming it. --log FILE writes every request (method, URL, body;
never headers, so never the token) as JSON lines.

Exit status: 0 done (a skipped Mapillary step included), 1 a step failed (each is named with why),
2 bad usage.
"""
import argparse
import datetime
import gzip
import hashlib
import http.client
import json
import math
import os
import re
import shutil
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

USER_AGENT = "kodama-dag-site-data/0.1 (scripts/site_data.py of the kodama-dag project)"
TRIES = 3
BACKOFF_S = 2.0  # then 4 s
TIMEOUT_S = 300  # per socket operation; Overpass may think for up to its [timeout:180]

# ---------------------------------------------------------------------------------------------
# Sites (docs/sites.md; /work/site-layout.md): CRS, SW origin, size, centre and WGS84 box W,S,E,N.

SITES = {
    "brooklyn": {
        "crs": "EPSG:32618", "origin": (584825, 4504973), "size_m": (1700, 700),
        "centre": (40.69436, -73.98597), "centre_source": "MetroTech Center (Wikipedia infobox)",
        "box": (-73.99607, 40.69129, -73.97586, 40.69742), "freqs": "6.75 and 16.95 GHz",
    },
    "boulder": {
        "crs": "EPSG:26913", "origin": (477332, 4426993), "size_m": (500, 500),
        "centre": (39.99507, -105.26261), "centre_source": "NIST00USA IGS station (ECEF)",
        "box": (-105.26553, 39.99281, -105.25969, 39.99733), "freqs": "28 GHz",
    },
    "painiitty": {
        "crs": "EPSG:3067", "origin": (379294, 6678946), "size_m": (1240, 1240),
        "centre": (60.23509, 24.83140), "centre_source": 'HSL city-bike station 757 "Painiitty"',
        "box": (24.82057, 60.22934, 24.84223, 60.24084), "freqs": "3.6 GHz",
    },
}
WIDEN_M = 200.0


def widened(box, metres=WIDEN_M):
    """The box widened by `metres` on every side (spherical degrees, rounded outwards to 1e-5)."""
    w, s, e, n = box
    dlat = metres / 111320.0
    dlon = metres / (111320.0 * math.cos(math.radians((s + n) / 2)))
    down = lambda v: math.floor(v * 1e5) / 1e5  # noqa: E731
    up = lambda v: math.ceil(v * 1e5) / 1e5  # noqa: E731
    return (down(w - dlon), down(s - dlat), up(e + dlon), up(n + dlat))


def contains(outer, inner):
    return outer[0] <= inner[0] and outer[1] <= inner[1] and outer[2] >= inner[2] and outer[3] >= inner[3]


def intersects(a, b):
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def fmt_box(b):
    return ",".join(f"{v:.5f}" for v in b)


# ---------------------------------------------------------------------------------------------
# Licences and non-public items.

LIC_3DEP = "public domain (USGS 3D Elevation Program; credit the USGS)"
LIC_NYC = ("NYC Open Data terms of use, https://www.nyc.gov/html/data/terms.html "
           "(metadata: Access Rights Public)")
LIC_NAIP = "public domain (USDA Farm Service Agency NAIP); Planetary Computer terms of use for its API"
LIC_OSM = "ODbL 1.0, (c) OpenStreetMap contributors"
LIC_SRTM = "public domain (NASA/USGS SRTM), via the AWS Terrain Tiles open data set"
LIC_COP = ("Copernicus DEM licence (free with attribution): (c) DLR e.V. 2010-2014 and (c) Airbus "
           "Defence and Space GmbH 2014-2018 provided under COPERNICUS by the European Union and ESA")
LIC_MLY = "CC BY-SA 4.0 (Mapillary contributors): keep the attribution with anything you publish"

NOT_PUBLIC = {
    "brooklyn": [
        ("measurements.csv",
         "20 fixed links (7 LOS + 13 NLOS) at 6.75 and 16.95 GHz, Shakya et al. 2025, arXiv 2410.17539",
         "Shakya et al. (NYU WIRELESS); published only as tables in the paper",
         "transcribe the paper's point-data tables into the project's CSV layout (README, \"Data\")"),
        ("view_outputs/", "your segmentation, material and depth models' outputs on the street views",
         "you", "run your models on mapillary/ (docs/datasets.md, \"Model outputs\")"),
    ],
    "boulder": [
        ("measurements.csv",
         "4,979 measurements at 28 GHz along robot trajectories (courtyard and walkway), NIST",
         "NIST (NextG Channel Model Alliance data portal, https://nextg.nist.gov/)",
         "request it on the portal and accept its data-sharing agreement; convert to the CSV layout"),
        ("nist_panoramas/", "the panoramic image sequences recorded during NIST's campaign (the paper's views)",
         "NIST (NextG portal, same data-sharing agreement)",
         "request with the measurements; the public stand-in is mapillary/"),
        ("view_outputs/", "your segmentation, material and depth models' outputs on the street views",
         "you", "run your models on mapillary/ (docs/datasets.md, \"Model outputs\")"),
    ],
    "painiitty": [
        ("measurements.csv", "the paper's industry drive test at 3.6 GHz (a private campaign)",
         "not named in the paper (its authors are at Nokia Bell Labs)",
         "not obtainable publicly; ask the paper's authors"),
        ("view_outputs/", "your segmentation, material and depth models' outputs on the street views",
         "you", "run your models on mapillary/ (docs/datasets.md, \"Model outputs\")"),
    ],
}

# Public, but fetched by hand: the paper's own sources where the recipe has a stand-in or none.
BY_HAND = {
    "brooklyn": [
        ("dem.tif", "the paper's DEM: NYC 2017 Topobathymetric LiDAR bare-earth DEM (1 ft cells, EPSG:2263, "
         "feet), NYC DoITT, via the NYS GIS Clearinghouse (https://gis.ny.gov/elevation); tiles seen "
         "(third-party code only) as https://gisdata.ny.gov/elevation/DEM/NYC_TopoBathymetric2017/be_NYC_<NNN>.tif, "
         "several hundred MB each",
         "no tile index verified: the recipe writes the USGS 3DEP 1 m DEM instead"),
        ("ortho.tif", "the paper's orthophoto: NYS Digital Orthoimagery Program 2024 (NYS GIS Clearinghouse, "
         "https://gis.ny.gov/); tiles seen (third-party code only) as "
         "https://gisdata.ny.gov/ortho/nysdop12/new_york_city/spcs/tiles/<tile>.zip",
         "zip contents unverified and several tiles need a mosaic (GDAL): the recipe writes NAIP instead"),
    ],
    "boulder": [
        ("lidar/", "the paper's LiDAR: DRCOG 2022 from the Colorado Spatial Data Portal",
         "portal URL unverified: the recipe fetches the DRCOG project's USGS 3DEP tiles (that they are "
         "the paper's DRCOG 2022 is unverified)"),
        ("ortho.tif", "the paper's NAIP 2021 Colorado from the Colorado Spatial Data Portal",
         "the recipe fetches the NAIP 2021 quarter-quad from the Planetary Computer"),
    ],
    "painiitty": [
        ("tiles/", "Helsinki 3D reality mesh 2017 (City of Helsinki, CC BY 4.0), published as OBJ and 3MX: "
         "https://www.hel.fi/fi/paatoksenteko-ja-hallinto/tietoa-helsingista/kartat-ja-paikkatieto/helsinki-3d",
         "no verified 3D Tiles endpoint: download the OBJ/3MX tiles over the site and convert them to "
         "3D Tiles (tileset.json); coverage of Painiitty (Espoo) unverified"),
    ],
}

# ---------------------------------------------------------------------------------------------
# HTTP: live (urllib) or replayed from recorded responses.


# What a request can fail with: an HTTP answer (HTTPError is a URLError), or the network.
NETWORK_ERRORS = (urllib.error.URLError, TimeoutError, ConnectionError, http.client.HTTPException)


class StepFailed(Exception):
    """A step that failed; `records` are the files it did get (SOURCES.md lists them)."""

    def __init__(self, message, records=()):
        super().__init__(message)
        self.records = list(records)


def each(items, fetch):
    """fetch(item) -> record for every item; the failures are gathered into one StepFailed that
    carries the records of the others."""
    recs, failed = [], []
    for item in items:
        try:
            recs.append(fetch(item))
        except StepFailed as e:
            failed.append(str(e))
    if failed:
        raise StepFailed(f"{len(failed)} of {len(items)} files failed: " + "; ".join(failed[:5]), recs)
    return recs


def shown(url):
    """The URL for printing: a signed query (SAS `sig=`, signed CDN URLs) is elided."""
    if re.search(r"[?&](sig|oh|_nc_sig|token|access_token)=", url):
        return url.split("?", 1)[0] + "?<signed>"
    return url


def human(n):
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    return str(n)


class Http:
    """Common request log; subclasses implement _open."""

    def __init__(self):
        self.log = []

    def record(self, method, url, body):
        self.log.append({"method": method, "url": url,
                         "body": body.decode("utf-8", "replace") if body else None})

    def fetch(self, url, *, method="GET", body=None, headers=None, content_type=None):
        """A small response (JSON, XML) as bytes."""
        self.record(method, url, body)
        return self._fetch(url, method, body, dict(headers or {}), content_type)

    def download(self, url, dest, *, expected_size=None, headers=None):
        """`url` to `dest` through `dest.part`; 'present' when kept, 'fetched' when written."""
        if dest.exists():
            size = dest.stat().st_size
            if expected_size is None or size == expected_size:
                print(f"  present {dest} ({human(size)})")
                return "present"
            print(f"  {dest}: {size} bytes where the source says {expected_size}: fetching again")
        self.record("GET", url, None)
        dest.parent.mkdir(parents=True, exist_ok=True)
        part = dest.with_name(dest.name + ".part")
        t0 = time.monotonic()
        self._download(url, part, dict(headers or {}))
        size = part.stat().st_size
        if expected_size is not None and size != expected_size:
            # The transfer itself was complete (its Content-Length was met): the index is stale.
            print(f"  warning: {dest.name}: {size} bytes where the index says {expected_size}; kept",
                  file=sys.stderr)
        os.replace(part, dest)
        dt = max(time.monotonic() - t0, 1e-6)
        print(f"  fetched {dest} ({human(size)}, {human(size / dt)}/s) from {shown(url)}")
        return "fetched"


class LiveHttp(Http):
    def _request(self, url, method, body, headers, content_type):
        headers.setdefault("User-Agent", USER_AGENT)
        if content_type:
            headers["Content-Type"] = content_type
        return urllib.request.Request(url, data=body, headers=headers, method=method)

    def _retry(self, url, attempt, why):
        if attempt >= TRIES:
            raise StepFailed(f"{shown(url)}: {why} (tried {TRIES} times)")
        wait = BACKOFF_S * 2 ** (attempt - 1)
        print(f"  {shown(url)}: {why}; trying again in {wait} s", file=sys.stderr)
        time.sleep(wait)

    def _retry_or_fail(self, url, attempt, e, note=""):
        """Waits to try again after a transient failure (a 429 or 5xx answer, a network error);
        raises StepFailed for any other HTTP answer, or once the tries are spent."""
        if isinstance(e, urllib.error.HTTPError):
            if e.code not in (429, 500, 502, 503, 504):
                raise StepFailed(f"{shown(url)}: HTTP {e.code} {e.reason}") from None
            self._retry(url, attempt, f"HTTP {e.code} {e.reason}")
        else:
            self._retry(url, attempt, f"{getattr(e, 'reason', e)}{note}")

    def _fetch(self, url, method, body, headers, content_type):
        for attempt in range(1, TRIES + 1):
            try:
                req = self._request(url, method, body, dict(headers), content_type)
                with urllib.request.urlopen(req, timeout=TIMEOUT_S) as r:
                    return r.read()
            except NETWORK_ERRORS as e:
                self._retry_or_fail(url, attempt, e)
        raise AssertionError("unreachable")

    def _download(self, url, part, headers):
        for attempt in range(1, TRIES + 1):
            have = part.stat().st_size if part.exists() else 0
            h = dict(headers)
            if have:
                h["Range"] = f"bytes={have}-"
            try:
                req = self._request(url, "GET", None, h, None)
                with urllib.request.urlopen(req, timeout=TIMEOUT_S) as r:
                    if have and r.status != 206:
                        have = 0  # the server ignored the range: start over
                    length = r.headers.get("Content-Length")
                    total = have + int(length) if length and length.isdigit() else None
                    with open(part, "ab" if have else "wb") as f:
                        done, last = have, 0.0
                        while True:
                            chunk = r.read(1 << 20)
                            if not chunk:
                                break
                            f.write(chunk)
                            done += len(chunk)
                            if sys.stderr.isatty() and time.monotonic() - last > 0.5:
                                last = time.monotonic()
                                pct = f" {100 * done / total:.0f}%" if total else ""
                                print(f"\r  {part.name}: {human(done)}{pct}   ", end="", file=sys.stderr)
                    if sys.stderr.isatty():
                        print("\r", end="", file=sys.stderr)
                    if total is not None and done < total:
                        raise ConnectionError(f"connection closed at {done} of {total} bytes")
                    return
            except urllib.error.HTTPError as e:
                if e.code == 416 and have:
                    part.unlink()  # the range is past the end: the .part is stale
                    self._retry(url, attempt, "stale partial file")
                    continue
                self._retry_or_fail(url, attempt, e)
            except NETWORK_ERRORS as e:
                self._retry_or_fail(url, attempt, e, f" (partial file kept: {part})")


class ReplayHttp(Http):
    """Answers from DIR/index.json; an unmatched request is an error naming it."""

    def __init__(self, folder):
        super().__init__()
        self.folder = Path(folder)
        index = self.folder / "index.json"
        try:
            self.entries = json.loads(index.read_text())["responses"]
        except (OSError, ValueError, KeyError) as e:
            print(f"site_data.py: --replay {folder}: cannot read {index}: {e}", file=sys.stderr)
            sys.exit(2)

    def _match(self, method, url, body=None):
        for e in self.entries:
            if e.get("method", "GET") != method:
                continue
            if "body_contains" in e and e["body_contains"].encode() not in (body or b""):
                continue
            if ("url" in e and e["url"] == url) or \
               ("url_prefix" in e and url.startswith(e["url_prefix"])) or \
               ("url_pattern" in e and re.fullmatch(e["url_pattern"], url)):
                return e
        raise StepFailed(f"replay: no recorded response for {method} {url}")

    def _body(self, method, url, body=None):
        e = self._match(method, url, body)
        status = e.get("status", 200)
        if status >= 400:
            raise StepFailed(f"{shown(url)}: HTTP {status} (recorded)")
        return (self.folder / e["file"]).read_bytes()

    def _fetch(self, url, method, body, headers, content_type):
        return self._body(method, url, body)

    def _download(self, url, part, headers):
        part.write_bytes(self._body("GET", url))


# ---------------------------------------------------------------------------------------------
# Checks on what came back (an HTML error page saved as a .tif is caught here).


def check_magic(path, kind):
    with open(path, "rb") as f:
        head = f.read(4)
    ok = {
        "tiff": head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"),
        "las": head[:4] == b"LASF",
    }[kind]
    if not ok:
        path.rename(path.with_name(path.name + ".bad"))
        raise StepFailed(f"{path}: not a {kind.upper()} file (starts {head!r}); moved to {path.name}.bad")


def json_of(data, what):
    try:
        return json.loads(data)
    except ValueError:
        raise StepFailed(f"{what}: the response is not JSON (starts {data[:80]!r})") from None


def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------
# Steps. Each has plan() (dry run: requests and files) and run() (returns source records).


class Ctx:
    def __init__(self, http, out, site, name, args):
        self.http, self.out, self.site, self.name, self.args = http, out, site, name, args
        self.root = out / name
        self.box = site["box"]
        self.dbox = widened(site["box"])
        self.today = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")

    def rel(self, path):
        return path.relative_to(self.out).as_posix()

    def record(self, path, dataset, url, licence, note=None):
        return {"path": self.rel(path), "dataset": dataset, "url": shown(url), "retrieved": self.today,
                "licence": licence, "bytes": path.stat().st_size, "sha256": sha256(path),
                **({"note": note} if note else {})}


TNM = "https://tnmaccess.nationalmap.gov/api/v1/products"


def tnm_url(dataset, fmt, box, offset=0):
    q = {"datasets": dataset, "bbox": fmt_box(box), "prodFormats": fmt, "max": "100", "offset": str(offset)}
    return TNM + "?" + urllib.parse.urlencode(q)


def tnm_items(ctx, dataset, fmt, box):
    items, offset = [], 0
    while True:
        url = tnm_url(dataset, fmt, box, offset)
        doc = json_of(ctx.http.fetch(url), url)
        if doc.get("errors") and not doc.get("items"):
            raise StepFailed(f"{url}: {doc['errors']}")
        page = doc.get("items") or []
        items += page
        offset += len(page)
        if not page or offset >= int(doc.get("total") or 0):
            return items


def tnm_box(item):
    b = item.get("boundingBox") or {}
    try:
        return (float(b["minX"]), float(b["minY"]), float(b["maxX"]), float(b["maxY"]))
    except (KeyError, TypeError, ValueError):
        return None


def basename_of(url):
    name = urllib.parse.unquote(urllib.parse.urlparse(url).path.rsplit("/", 1)[-1])
    if not name or name in (".", "..") or "/" in name or "\\" in name:
        raise StepFailed(f"{shown(url)}: no usable file name")
    return name


class TnmLidar:
    name = "lidar"

    def __init__(self, project):
        self.project = project

    def plan(self, ctx):
        return [f"GET {tnm_url('Lidar Point Cloud (LPC)', 'LAS,LAZ', ctx.box)} (pages of 100)",
                f"then GET each listed tile of {self.project} -> {ctx.name}/lidar/<tile file name>"]

    def run(self, ctx):
        items = tnm_items(ctx, "Lidar Point Cloud (LPC)", "LAS,LAZ", ctx.box)
        mine = [i for i in items if i.get("downloadURL") and self.project.lower() in (i.get("title", "") + i.get("downloadURL", "")).lower()
                and (tnm_box(i) is None or intersects(tnm_box(i), ctx.box))]
        if not mine:
            seen = sorted({i.get("title", "?") for i in items})[:10]
            raise StepFailed(f"TNM lists no {self.project} LiDAR tile over the site box "
                             f"{fmt_box(ctx.box)}; it lists: {seen or 'nothing'}")
        def fetch(i):
            dest = ctx.root / "lidar" / basename_of(i["downloadURL"])
            ctx.http.download(i["downloadURL"], dest, expected_size=i.get("sizeInBytes"))
            check_magic(dest, "las")
            return ctx.record(dest, f"USGS 3DEP Lidar Point Cloud: {i.get('title', '?')}", i["downloadURL"], LIC_3DEP)

        return each(sorted(mine, key=lambda i: i["downloadURL"]), fetch)


class TnmDem:
    name = "dem"

    def __init__(self, prefer=None, note=None):
        self.prefer, self.note = prefer, note

    def plan(self, ctx):
        return [f"GET {tnm_url('Digital Elevation Model (DEM) 1 meter', 'GeoTIFF', ctx.box)}",
                f"then GET the tile whose footprint contains the site box -> {ctx.name}/dem.tif"]

    def run(self, ctx):
        items = tnm_items(ctx, "Digital Elevation Model (DEM) 1 meter", "GeoTIFF", ctx.box)
        covering = [i for i in items if tnm_box(i) and contains(tnm_box(i), ctx.box) and i.get("downloadURL")]
        if not covering:
            raise StepFailed(
                f"no single USGS 1 m DEM tile contains the site box {fmt_box(ctx.box)} (TNM lists "
                f"{len(items)} tiles over it); mosaic them by hand: gdalbuildvrt dem.vrt <tiles>.tif && "
                f"gdal_translate -projwin_srs EPSG:4326 -projwin W N E S dem.vrt {ctx.name}/dem.tif")
        pref = (lambda i: self.prefer.lower() in i.get("title", "").lower()) if self.prefer else (lambda i: True)
        best = max(covering, key=lambda i: (pref(i), i.get("publicationDate", ""), i["downloadURL"]))
        dest = ctx.root / "dem.tif"
        ctx.http.download(best["downloadURL"], dest, expected_size=best.get("sizeInBytes"))
        check_magic(dest, "tiff")
        return [ctx.record(dest, f"USGS 3DEP 1 m DEM: {best.get('title', '?')}", best["downloadURL"],
                           LIC_3DEP, self.note)]


NYS_LAS = "https://orthos.its.ny.gov/arcgis/rest/services/vector/las_indexes/MapServer"
NYC_LAS_BASE = "https://gisdata.ny.gov/elevation/LIDAR/NYC_TopoBathymetric2017"


class NysLidar:
    name = "lidar"

    def query_url(self, layer, box):
        q = {"where": "1=1", "geometry": fmt_box(box), "geometryType": "esriGeometryEnvelope",
             "inSR": "4326", "spatialRel": "esriSpatialRelIntersects", "outFields": "*",
             "returnGeometry": "false", "f": "json"}
        return f"{NYS_LAS}/{layer}/query?" + urllib.parse.urlencode(q)

    def plan(self, ctx):
        layer = ctx.args.nys_las_layer
        first = [] if layer is not None else [f"GET {NYS_LAS}?f=json (find the NYC 2017 layer by name)"]
        return first + [f"GET {self.query_url(layer if layer is not None else '<layer>', ctx.box)}",
                        f"then GET each tile's DIRECT_DL (else {NYC_LAS_BASE}/<FILENAME>) -> "
                        f"{ctx.name}/lidar/<FILENAME>"]

    def layer(self, ctx):
        if ctx.args.nys_las_layer is not None:
            return ctx.args.nys_las_layer
        url = f"{NYS_LAS}?f=json"
        layers = json_of(ctx.http.fetch(url), url).get("layers") or []
        hits = [lay for lay in layers if re.search(r"nyc|new york city", lay.get("name", ""), re.I)
                and "2017" in lay.get("name", "")]
        if len(hits) != 1:
            names = [f"{lay.get('id')}: {lay.get('name')}" for lay in layers]
            raise StepFailed(f"{url}: expected one layer named for NYC 2017, found {len(hits)} among {names}; "
                             f"pass --nys-las-layer ID")
        return hits[0]["id"]

    def run(self, ctx):
        url = self.query_url(self.layer(ctx), ctx.box)
        doc = json_of(ctx.http.fetch(url), url)
        if "error" in doc:
            raise StepFailed(f"{url}: {doc['error']}")
        attrs = [f.get("attributes") or {} for f in doc.get("features") or []]
        if not attrs:
            raise StepFailed(f"{url}: no LAS tile over the site box {fmt_box(ctx.box)}")
        for a in attrs:
            if not a.get("FILENAME"):
                raise StepFailed(f"{url}: a tile without FILENAME (fields: {sorted(a)})")

        def fetch(a):
            src = a.get("DIRECT_DL") or f"{NYC_LAS_BASE}/{a['FILENAME']}"
            dest = ctx.root / "lidar" / basename_of(src)
            ctx.http.download(src, dest)
            check_magic(dest, "las")
            return ctx.record(dest, f"NYC 2017 Topobathymetric LiDAR tile {a['FILENAME']} (EPSG:2263, US ft)",
                              src, LIC_NYC)

        return each(sorted(attrs, key=lambda a: str(a["FILENAME"])), fetch)


PC_STAC = "https://planetarycomputer.microsoft.com/api/stac/v1/search"
PC_TOKEN = "https://planetarycomputer.microsoft.com/api/sas/v1/token/naip"


class Naip:
    name = "ortho"

    def __init__(self, year=None, note=None):
        self.year, self.note = year, note

    def body(self, ctx):
        q = {"collections": ["naip"], "bbox": [round(v, 5) for v in ctx.box], "limit": 100}
        if self.year:
            q["datetime"] = f"{self.year}-01-01T00:00:00Z/{self.year}-12-31T23:59:59Z"
        return json.dumps(q, sort_keys=True).encode()

    def plan(self, ctx):
        return [f"POST {PC_STAC} {self.body(ctx).decode()}",
                f"GET {PC_TOKEN}",
                f"then GET the containing item's assets.image.href + '?' + token -> {ctx.name}/ortho.tif"]

    def run(self, ctx):
        doc = json_of(ctx.http.fetch(PC_STAC, method="POST", body=self.body(ctx),
                                     content_type="application/json"), PC_STAC)
        feats = [f for f in doc.get("features") or []
                 if f.get("bbox") and contains(f["bbox"], ctx.box) and (f.get("assets") or {}).get("image")]
        if not feats:
            raise StepFailed(f"no NAIP{' ' + str(self.year) if self.year else ''} item contains the site box "
                             f"{fmt_box(ctx.box)} ({len(doc.get('features') or [])} intersect it); mosaic them "
                             f"by hand with gdalbuildvrt and gdal_translate -projwin")
        year = lambda f: str((f.get("properties") or {}).get("naip:year", ""))  # noqa: E731
        best = max(feats, key=lambda f: (year(f), f.get("id", "")))
        token = json_of(ctx.http.fetch(PC_TOKEN), PC_TOKEN).get("token")
        if not token:
            raise StepFailed(f"{PC_TOKEN}: no token in the response")
        href = best["assets"]["image"]["href"]
        dest = ctx.root / "ortho.tif"
        ctx.http.download(href + ("&" if "?" in href else "?") + token, dest)
        check_magic(dest, "tiff")
        return [ctx.record(dest, f"USDA NAIP {year(best)} quarter-quad {best.get('id')} "
                           f"(Planetary Computer STAC, collection naip)", href, LIC_NAIP, self.note)]


OVERPASS = "https://overpass-api.de/api/interpreter"


def overpass_query(box):
    w, s, e, n = box
    b = f"{s:.5f},{w:.5f},{n:.5f},{e:.5f}"
    return (f"[out:xml][timeout:180];\n(\n  way[\"building\"]({b});\n  relation[\"building\"]({b});\n"
            f"  way[\"building:part\"]({b});\n  relation[\"building:part\"]({b});\n);\n"
            f"out body;\n>;\nout skel qt;\n")


class Osm:
    name = "osm"

    def plan(self, ctx):
        return [f"POST {OVERPASS} data={overpass_query(ctx.dbox)!r}", f"-> {ctx.name}/osm.osm"]

    def run(self, ctx):
        dest = ctx.root / "osm.osm"
        if dest.exists():
            print(f"  present {dest} ({human(dest.stat().st_size)})")
        else:
            body = urllib.parse.urlencode({"data": overpass_query(ctx.dbox)}).encode()
            data = ctx.http.fetch(OVERPASS, method="POST", body=body,
                                  content_type="application/x-www-form-urlencoded")
            if b"<osm" not in data[:500]:
                raise StepFailed(f"{OVERPASS}: the answer is not OSM XML (starts {data[:120]!r})")
            if b"<remark>" in data:
                remark = re.search(rb"<remark>(.*?)</remark>", data, re.S)
                raise StepFailed(f"{OVERPASS}: the query did not finish: "
                                 f"{remark.group(1).decode('utf-8', 'replace').strip() if remark else '?'}")
            dest.parent.mkdir(parents=True, exist_ok=True)
            part = dest.with_name(dest.name + ".part")
            part.write_bytes(data)
            os.replace(part, dest)
            print(f"  fetched {dest} ({human(len(data))}) from {OVERPASS}")
        return [ctx.record(dest, "OpenStreetMap buildings via the Overpass API, download box "
                           f"{fmt_box(ctx.dbox)}", OVERPASS, LIC_OSM,
                           "query: " + overpass_query(ctx.dbox).replace("\n", " "))]


SKADI = "https://elevation-tiles-prod.s3.amazonaws.com/skadi"


def skadi_tiles(box):
    w, s, e, n = box
    out = []
    for lat in range(math.floor(s), math.floor(n) + 1):
        for lon in range(math.floor(w), math.floor(e) + 1):
            out.append(f"{'N' if lat >= 0 else 'S'}{abs(lat):02d}{'E' if lon >= 0 else 'W'}{abs(lon):03d}")
    return out


class Srtm:
    name = "srtm"

    def plan(self, ctx):
        return [f"GET {SKADI}/{t[:3]}/{t}.hgt.gz -> gunzip -> {ctx.name}/srtm/{t}.hgt" for t in skadi_tiles(ctx.dbox)]

    def run(self, ctx):
        recs = []
        for t in skadi_tiles(ctx.dbox):
            url = f"{SKADI}/{t[:3]}/{t}.hgt.gz"
            dest = ctx.root / "srtm" / f"{t}.hgt"
            if dest.exists():
                print(f"  present {dest} ({human(dest.stat().st_size)})")
            else:
                gz = dest.with_name(dest.name + ".gz")
                ctx.http.download(url, gz)
                part = dest.with_name(dest.name + ".part")
                try:
                    with gzip.open(gz, "rb") as src, open(part, "wb") as dst:
                        shutil.copyfileobj(src, dst, 1 << 20)
                except (OSError, EOFError) as e:
                    raise StepFailed(f"{gz}: not a gzip file ({e}); delete it and run again") from None
                size = part.stat().st_size
                if size not in (3601 * 3601 * 2, 1201 * 1201 * 2):
                    raise StepFailed(f"{url}: unpacked to {size} bytes, not a 3601 x 3601 or 1201 x 1201 "
                                     f"16-bit grid (kept as {part})")
                os.replace(part, dest)
                gz.unlink()
                print(f"  unpacked {dest} ({human(size)})")
            recs.append(ctx.record(dest, f"SRTM 1 arc-second tile {t} (Terrain Tiles on AWS, skadi)",
                                   url, LIC_SRTM))
        return recs


COP = "https://copernicus-dem-30m.s3.amazonaws.com"


class Copernicus:
    name = "dem30"

    def url(self, ctx):
        lat, lon = math.floor(ctx.site["centre"][0]), math.floor(ctx.site["centre"][1])
        t = f"Copernicus_DSM_COG_10_{'N' if lat >= 0 else 'S'}{abs(lat):02d}_00_{'E' if lon >= 0 else 'W'}{abs(lon):03d}_00_DEM"
        return f"{COP}/{t}/{t}.tif", t

    def plan(self, ctx):
        return [f"GET {self.url(ctx)[0]} -> {ctx.name}/dem30.tif"]

    def run(self, ctx):
        url, tile = self.url(ctx)
        if len(skadi_tiles(ctx.dbox)) != 1:
            raise StepFailed(f"the download box {fmt_box(ctx.dbox)} crosses a degree line: one GLO-30 tile "
                             f"does not cover it")
        dest = ctx.root / "dem30.tif"
        ctx.http.download(url, dest)
        check_magic(dest, "tiff")
        return [ctx.record(dest, f"Copernicus DEM GLO-30 tile {tile} (AWS open data)", url, LIC_COP)]


MLY = "https://graph.mapillary.com/images"
MLY_FIELDS = ("id,computed_geometry,geometry,computed_altitude,altitude,computed_rotation,"
              "computed_compass_angle,compass_angle,camera_type,camera_parameters,exif_orientation,"
              "width,height,captured_at,sequence,quality_score,thumb_original_url")
MLY_LIMIT = 2000
TOKEN_HELP = ("MAPILLARY_TOKEN is not set: skipping the street views. Get a client token from "
              "https://www.mapillary.com/dashboard/developers (register an application; its client "
              "token starts with MLY|), then `export MAPILLARY_TOKEN='MLY|...'` and run this step again "
              "(--only mapillary). The token goes in the environment, not on the command line, where "
              "ps and the shell history would show it.")


def mly_url(box):
    q = {"bbox": fmt_box(box), "fields": MLY_FIELDS, "limit": str(MLY_LIMIT)}
    return MLY + "?" + urllib.parse.urlencode(q)


def quarters(box):
    w, s, e, n = box
    cx, cy = (w + e) / 2, (s + n) / 2
    return [(w, s, cx, cy), (cx, s, e, cy), (w, cy, cx, n), (cx, cy, e, n)]


class Mapillary:
    name = "mapillary"

    def plan(self, ctx):
        return [f"GET {mly_url(ctx.dbox)} (header Authorization: OAuth $MAPILLARY_TOKEN; follows "
                f"paging.next; a box that hits {MLY_LIMIT} images is split in four)",
                f"then GET each image's thumb_original_url -> {ctx.name}/mapillary/<id>.jpg",
                f"write {ctx.name}/mapillary/images.json ({{\"data\": [entities]}})"]

    def entities(self, ctx, headers, box, depth=0):
        url, got = mly_url(box), []
        while url:
            try:
                doc = json_of(ctx.http.fetch(url, headers=headers), url.split("?")[0])
            except StepFailed as e:
                if re.search(r"HTTP 40[13]", str(e)):
                    raise StepFailed(f"{e}: is MAPILLARY_TOKEN a valid client token?") from None
                raise
            if "error" in doc:
                raise StepFailed(f"{MLY}: {doc['error'].get('message', doc['error'])}")
            got += doc.get("data") or []
            url = (doc.get("paging") or {}).get("next")
        if len(got) >= MLY_LIMIT and depth < 4:
            got = [x for q in quarters(box) for x in self.entities(ctx, headers, q, depth + 1)]
        return got

    def run(self, ctx):
        token = os.environ.get("MAPILLARY_TOKEN", "").strip()
        if not token:
            print(f"  skipped: {TOKEN_HELP}")
            return "skipped"
        headers = {"Authorization": f"OAuth {token}"}
        seen, ents = set(), []
        for ent in self.entities(ctx, headers, ctx.dbox):
            if str(ent.get("id")) not in seen:
                seen.add(str(ent.get("id")))
                ents.append(ent)
        if ctx.args.max_images is not None:
            ents = sorted(ents, key=lambda x: str(x["id"]))[: ctx.args.max_images]
        print(f"  {len(ents)} images in the download box {fmt_box(ctx.dbox)}")
        folder, kept, failed = ctx.root / "mapillary", [], []
        for ent in ents:
            iid, src = str(ent["id"]), ent.get("thumb_original_url")
            if not re.fullmatch(r"[0-9A-Za-z_-]+", iid) or not src:
                failed.append(f"{iid}: no usable id or thumb_original_url")
                continue
            try:
                ctx.http.download(src, folder / f"{iid}.jpg")
                kept.append(ent)
            except StepFailed as e:
                failed.append(str(e))
        folder.mkdir(parents=True, exist_ok=True)
        listing = folder / "images.json"
        part = listing.with_name(listing.name + ".part")
        part.write_text(json.dumps({"data": kept}, indent=1) + "\n")
        os.replace(part, listing)
        recs = [ctx.record(listing, f"Mapillary API v4 image entities ({len(kept)} images; the images "
                           f"are mapillary/<id>.jpg)", mly_url(ctx.dbox), LIC_MLY)]
        if failed:
            raise StepFailed(f"{len(failed)} of {len(ents)} images failed (the others are kept and listed): "
                             + "; ".join(failed[:5]), recs)
        return recs


class HelsinkiMesh:
    name = "tiles"
    PAGE = "https://www.hel.fi/fi/paatoksenteko-ja-hallinto/tietoa-helsingista/kartat-ja-paikkatieto/helsinki-3d"

    def plan(self, ctx):
        return [f"(no request: no verified 3D Tiles endpoint) -> {ctx.name}/tiles/tileset.json by hand"]

    def run(self, ctx):
        done = ctx.root / "tiles" / "tileset.json"
        if done.exists():
            print(f"  present {done} (put there by hand)")
            return [ctx.record(done, "Helsinki 3D reality mesh 2017 as 3D Tiles, converted by hand from the "
                               "city's OBJ/3MX", self.PAGE, "CC BY 4.0 (City of Helsinki)")]
        raise StepFailed(
            "by hand: no 3D Tiles endpoint for the Helsinki 3D reality mesh (2017) could be verified. "
            f"Download the mesh tiles covering the site as OBJ or 3MX from the city's open data ({self.PAGE}; "
            "CC BY 4.0; ETRS-GK25 EPSG:3879 + N2000), convert them to OGC 3D Tiles and put tileset.json "
            f"and its content under {ctx.name}/tiles/. Whether the 2017 mesh reaches Painiitty (in "
            "Espoo, west of the Helsinki city line) is unverified. See docs/sites.md#painiitty.")


STEPS = {
    "brooklyn": [
        NysLidar(),
        TnmDem(note="public stand-in for the NYC 2017 bare-earth DEM the paper used (docs/sites.md#brooklyn)"),
        Naip(note="public stand-in for the NYS 2024 orthophoto the paper used (docs/sites.md#brooklyn)"),
        Osm(), Srtm(), Mapillary(),
    ],
    "boulder": [
        TnmLidar("DRCOG"), TnmDem(prefer="DRCOG"),
        Naip(year=2021, note="the paper's NAIP 2021 Colorado, here from the Planetary Computer "
             "rather than the Colorado portal"),
        Osm(), Srtm(), Mapillary(),
    ],
    "painiitty": [HelsinkiMesh(), Osm(), Copernicus(), Mapillary()],
}
ALL_STEPS = sorted({s.name for steps in STEPS.values() for s in steps})

# ---------------------------------------------------------------------------------------------
# SOURCES.md / sources.json.


def write_sources(ctx, records, failures, skipped):
    js = ctx.root / "sources.json"
    old = {}
    if js.exists():
        try:
            old = {r["path"]: r for r in json.loads(js.read_text()).get("files", [])}
        except (ValueError, KeyError, TypeError):
            old = {}
    for r in records:
        old[r["path"]] = r
    files = [old[k] for k in sorted(old)]
    site = ctx.site
    doc = {"site": ctx.name, "crs": site["crs"], "origin": list(site["origin"]), "size_m": list(site["size_m"]),
           "box_wgs84": list(site["box"]), "download_box_wgs84": list(ctx.dbox), "files": files,
           "not_downloadable": [{"path": p, "what": w, "holder": h, "how": how}
                                for p, w, h, how in NOT_PUBLIC[ctx.name]],
           "by_hand": [{"path": p, "source": w, "why": why} for p, w, why in BY_HAND[ctx.name]]}
    ctx.root.mkdir(parents=True, exist_ok=True)
    js.write_text(json.dumps(doc, indent=1) + "\n")
    lines = [f"# {ctx.name}: where each file came from",
             "",
             f"Written by `scripts/site_data.py {ctx.name}` on {ctx.today} (UTC). Site: {site['crs']}, "
             f"SW origin {site['origin']}, {site['size_m'][0]} x {site['size_m'][1]} m; centre "
             f"{site['centre'][0]}, {site['centre'][1]} ({site['centre_source']}); WGS84 box W,S,E,N "
             f"{fmt_box(site['box'])}; download box (+200 m) {fmt_box(ctx.dbox)}. Paper frequencies: "
             f"{site['freqs']}. See docs/sites.md#{ctx.name}.",
             "",
             "## Downloaded",
             "",
             "| file | dataset | source URL | retrieved | licence | bytes | sha256 |",
             "|---|---|---|---|---|---|---|"]
    for r in files:
        note = f" ({r['note']})" if r.get("note") else ""
        lines.append(f"| `{r['path']}` | {r['dataset']}{note} | {r['url']} | {r['retrieved']} | {r['licence']} "
                     f"| {r['bytes']} | `{r['sha256']}` |")
    if not files:
        lines.append("| (nothing yet) | | | | | | |")
    lines += ["", "## Not downloadable", "",
              "| file | what | holder | how to obtain |", "|---|---|---|---|"]
    for p, w, h, how in NOT_PUBLIC[ctx.name]:
        lines.append(f"| `{ctx.name}/{p}` | {w} | {h} | {how} |")
    lines += ["", "## Public, by hand", "",
              "| file | source | why by hand |", "|---|---|---|"]
    for p, what, why in BY_HAND[ctx.name]:
        lines.append(f"| `{ctx.name}/{p}` | {what} | {why} |")
    if failures or skipped:
        lines += ["", "## Not fetched in the last run", ""]
        lines += [f"- `{n}`: {why}" for n, why in failures]
        lines += [f"- `{n}`: skipped: {why}" for n, why in skipped]
    (ctx.root / "SOURCES.md").write_text("\n".join(lines) + "\n")


# ---------------------------------------------------------------------------------------------


def parse_args(argv):
    p = argparse.ArgumentParser(prog="site_data.py", description=__doc__.split("\n\n")[0],
                                epilog=__doc__.split("\n\n", 2)[2],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("site", choices=sorted(SITES) + ["all"])
    p.add_argument("--out", required=True, type=Path, help="the data folder (graphs read DATA/<site>/...)")
    p.add_argument("--only", help=f"comma-separated steps: {', '.join(ALL_STEPS)}")
    p.add_argument("--dry-run", action="store_true", help="print requests and files; send and write nothing")
    p.add_argument("--replay", type=Path, metavar="DIR", help="answer requests from DIR/index.json")
    p.add_argument("--log", type=Path, metavar="FILE", help="write every request as JSON lines (no headers)")
    p.add_argument("--max-images", type=int, metavar="N", help="keep at most N Mapillary images per site")
    p.add_argument("--nys-las-layer", type=int, metavar="ID",
                   help="the NYS las_indexes MapServer layer of NYC 2017 (default: found by name)")
    args = p.parse_args(argv)
    only = None
    if args.only:
        only = [s.strip() for s in args.only.split(",") if s.strip()]
        bad = [s for s in only if s not in ALL_STEPS]
        if bad or not only:
            p.error(f"--only: unknown step(s) {bad}; steps are {', '.join(ALL_STEPS)}")
        names = ["brooklyn", "boulder", "painiitty"] if args.site == "all" else [args.site]
        have = {s.name for n in names for s in STEPS[n]}
        if not set(only) & have:
            p.error(f"--only {args.only}: {args.site} has none of these steps (it has {', '.join(sorted(have))})")
    args.only_steps = only
    return args


def report_manual(name):
    for p, w, h, how in NOT_PUBLIC[name]:
        print(f"  not downloadable: {name}/{p}: {w}; holder {h}; {how}")
    for p, w, why in BY_HAND[name]:
        print(f"  by hand (public): {name}/{p}: {w}; {why}")


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    names = ["brooklyn", "boulder", "painiitty"] if args.site == "all" else [args.site]
    http = ReplayHttp(args.replay) if args.replay else LiveHttp()
    failures_all = []
    for name in names:
        ctx = Ctx(http, args.out, SITES[name], name, args)
        steps = [s for s in STEPS[name] if args.only_steps is None or s.name in args.only_steps]
        if not steps:
            continue
        print(f"== {name}: {SITES[name]['crs']}, box {fmt_box(ctx.box)}, download box {fmt_box(ctx.dbox)}")
        if args.dry_run:
            print("  (dry run: nothing is sent or written; requests after an index query follow from its answer)")
            for s in steps:
                print(f"[{s.name}]")
                for line in s.plan(ctx):
                    print(f"  {line}")
            print(f"[sources] -> {name}/SOURCES.md, {name}/sources.json")
            report_manual(name)
            continue
        records, failures, skipped = [], [], []
        for s in steps:
            print(f"[{s.name}]")
            try:
                got = s.run(ctx)
                if got == "skipped":
                    skipped.append((s.name, "MAPILLARY_TOKEN not set"))
                else:
                    records += got
            except StepFailed as e:
                print(f"  FAILED {name}/{s.name}: {e}", file=sys.stderr)
                failures.append((s.name, str(e)))
                records += e.records
            except OSError as e:
                print(f"  FAILED {name}/{s.name}: {e}", file=sys.stderr)
                failures.append((s.name, str(e)))
            except (KeyError, TypeError, ValueError, AttributeError) as e:
                why = f"an answer of an unexpected shape ({type(e).__name__}: {e})"
                print(f"  FAILED {name}/{s.name}: {why}", file=sys.stderr)
                failures.append((s.name, why))
        report_manual(name)
        write_sources(ctx, records, failures, skipped)
        print(f"  wrote {ctx.root / 'SOURCES.md'}")
        failures_all += [(name, n, why) for n, why in failures]
    if args.log:
        args.log.write_text("".join(json.dumps(r) + "\n" for r in http.log))
    if failures_all:
        print(f"\n{len(failures_all)} step(s) failed:", file=sys.stderr)
        for site, n, why in failures_all:
            print(f"  {site}/{n}: {why}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
