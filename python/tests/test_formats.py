"""Outputs checked with the tools users open them in: a raster `.tif` through GDAL (rasterio) and
rio-cogeo's Cloud-Optimized GeoTIFF validator (GDAL's validate_cloud_optimized_geotiff rules);
footprints as a GeoPackage through GDAL's GeoPackage driver (pyogrio)."""

import os
from pathlib import Path

import numpy as np
import pytest

import kodama_dag

HERE = Path(__file__).parent


def _need(module: str):
    """The module, or a skip saying so; under CI=true its absence fails (.ci/run installs it)."""
    try:
        return __import__(module)
    except ImportError:
        if os.environ.get("CI") == "true":
            pytest.fail(f"{module} is not installed: .ci/run installs it for this test")
        pytest.skip(f"{module} is not installed (pip install rasterio rio-cogeo)")


def test_a_raster_tif_is_a_valid_cloud_optimized_geotiff(tmp_path):
    rasterio = _need("rasterio")
    _need("rio_cogeo")
    from rio_cogeo.cogeo import cog_validate

    run = kodama_dag.run(HERE / "rasters.ron", cache=tmp_path / "c", out=False, quiet=True,
                         targets=["wide"])
    tif = run.export("wide", tmp_path / "wide.tif")
    valid, errors, warnings = cog_validate(str(tif))
    assert valid and not errors, (errors, warnings)
    data, transform = run.raster("wide", xarray=False)
    with rasterio.open(tif) as src:
        assert src.crs.to_epsg() == 32618
        assert src.transform.to_gdal() == pytest.approx(transform)
        assert np.isnan(src.nodata)
        assert src.block_shapes == [(512, 512)]
        assert src.compression.name == "deflate"
        assert src.overviews(1) == [2, 4]
        got = src.read(1)
        # An overview, GDAL's reading of it: the mean of each 2 x 2 block's valid cells.
        ovr = src.read(1, out_shape=(src.height // 2, src.width // 2))
    assert got.shape == data.shape
    assert np.array_equal(np.isnan(got), np.isnan(data))
    assert np.array_equal(got[~np.isnan(got)], data[~np.isnan(data)])
    blocks = data[: 2 * ovr.shape[0], : 2 * ovr.shape[1]].reshape(ovr.shape[0], 2, ovr.shape[1], 2)
    assert np.allclose(ovr, np.nanmean(blocks, axis=(1, 3)), atol=1e-4, equal_nan=True)


def test_footprints_as_a_geopackage_read_through_gdal_as_the_geojson(tmp_path):
    """The `.gpkg` export through GDAL's GeoPackage driver (pyogrio): same features, attributes,
    CRS and geometry as the GeoJSON export read through the same driver."""
    pyogrio = _need("pyogrio")
    run = kodama_dag.run(HERE / "small.ron", cache=tmp_path / "c", out=False, quiet=True,
                         targets=["footprints"])
    gpkg = run.export("footprints", tmp_path / "footprints.gpkg")
    geojson = run.export("footprints", tmp_path / "footprints.geojson")
    info = pyogrio.read_info(gpkg)
    assert info["crs"] == "EPSG:32618"
    assert info["geometry_type"] == "MultiPolygon"
    assert info["features"] == len(run.artifact("footprints")["items"])
    assert list(info["fields"]) == ["id", "height_m", "min_height_m", "levels", "min_level",
                                    "area_m2"]
    meta_g, fid_g, geom_g, fields_g = pyogrio.raw.read(gpkg)
    meta_j, fid_j, geom_j, fields_j = pyogrio.raw.read(geojson)
    assert meta_g["crs"] == meta_j["crs"] == "EPSG:32618"
    # The same ids, heights and areas, feature by feature.
    names_g, names_j = list(meta_g["fields"]), list(meta_j["fields"])
    for name in ("id", "height_m", "area_m2"):
        g, j = fields_g[names_g.index(name)], fields_j[names_j.index(name)]
        assert list(g) == list(j), name
    # The same geometry: WKB from GDAL, compared as coordinates.
    shapely = _need("shapely")
    for wg, wj in zip(geom_g, geom_j):
        sg, sj = shapely.from_wkb(wg), shapely.from_wkb(wj)
        assert shapely.equals_exact(sg, sj, tolerance=1e-6), (sg.wkt[:200], sj.wkt[:200])
        assert sg.area > 0


def test_a_rasters_band_says_its_unit_and_the_node_that_made_it(tmp_path):
    """GDAL reads the band's unit and description from the GeoTIFF (GDAL_METADATA): heights in
    metres, through a blur (the unit followed upstream), labels without one; the same whether
    the file is a graph output or `Run.export`."""
    rasterio = _need("rasterio")
    graph = tmp_path / "units.ron"
    graph.write_text((HERE / "small.ron").read_text().replace(
        '"dsm_stats":  RasterStats(raster: "dsm"),',
        '"dsm_stats":  RasterStats(raster: "dsm"),\n'
        '        "smooth":     GaussianBlur(raster: "dsm", sigma_m: 1.0),\n'
        '        "count":      RasterizeSurface(points: "lidar", mode: Count),',
    ))
    out = tmp_path / "out"
    run = kodama_dag.run(graph, cache=tmp_path / "c", out=out, quiet=True)
    assert run.node("dsm").unit == "m" and run.node("count").unit is None
    with rasterio.open(out / "dsm.tif") as src:
        assert src.units == ("m",)
        assert src.descriptions == ("dsm (RasterizeSurface)",)
    for node, unit in (("smooth", "m"), ("count", None)):
        tif = run.export(node, tmp_path / f"{node}.tif")
        with rasterio.open(tif) as src:
            assert src.units == (unit,), node
            assert src.descriptions[0].startswith(node + " ("), src.descriptions
