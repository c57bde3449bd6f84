#!/usr/bin/env python3
"""GeoTIFFs written by GDAL (through rasterio), for tests that our reader reads another tool's
files correctly. Values follow formulas the tests recompute, so nothing is copied by hand.

    pip install rasterio && python3 scripts/make_geotiff_fixtures.py

Writes tests/fixtures/:
- gdal_dem_f32.tif: 40 x 30 float32, DEFLATE, EPSG:32618, 2 m pixels, north-west corner
  (583200, 4506660); z = 100 + 0.5 col - 0.25 row; nodata -9999 at (col 3, row 4), (10, 20).
- gdal_u16_tiled.tif: 64 x 48 uint16, 16 x 16 tiles, LZW, EPSG:28992, 0.5 m pixels, corner
  (84800, 447650); v = 7 col + 3 row; no nodata.
- gdal_ortho_rgb.tif: 20 x 10 RGB uint8, pixel-interleaved, EPSG:32618, 1 m pixels, corner
  (583210, 4506650); (r, g, b) = (10 col, 20 row, 7).
"""
from pathlib import Path

import numpy as np
import rasterio
from rasterio.transform import from_origin

OUT = Path(__file__).resolve().parent.parent / "tests" / "fixtures"


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    rows, cols = np.mgrid[0:30, 0:40]
    dem = (100 + 0.5 * cols - 0.25 * rows).astype("float32")
    dem[4, 3] = -9999
    dem[20, 10] = -9999
    with rasterio.open(OUT / "gdal_dem_f32.tif", "w", driver="GTiff", width=40, height=30, count=1,
                       dtype="float32", crs="EPSG:32618", transform=from_origin(583200, 4506660, 2, 2),
                       nodata=-9999, compress="deflate") as f:
        f.write(dem, 1)

    rows, cols = np.mgrid[0:48, 0:64]
    u16 = (7 * cols + 3 * rows).astype("uint16")
    with rasterio.open(OUT / "gdal_u16_tiled.tif", "w", driver="GTiff", width=64, height=48, count=1,
                       dtype="uint16", crs="EPSG:28992", transform=from_origin(84800, 447650, 0.5, 0.5),
                       tiled=True, blockxsize=16, blockysize=16, compress="lzw") as f:
        f.write(u16, 1)

    rows, cols = np.mgrid[0:10, 0:20]
    rgb = np.stack([10 * cols, 20 * rows, np.full_like(cols, 7)]).astype("uint8")
    with rasterio.open(OUT / "gdal_ortho_rgb.tif", "w", driver="GTiff", width=20, height=10, count=3,
                       dtype="uint8", crs="EPSG:32618", transform=from_origin(583210, 4506650, 1, 1),
                       interleave="pixel", photometric="RGB") as f:
        f.write(rgb)
    print("wrote", *sorted(p.name for p in OUT.glob("gdal_*.tif")))


if __name__ == "__main__":
    main()
