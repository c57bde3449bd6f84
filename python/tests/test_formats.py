"""Outputs checked with the tools users open them in: a raster `.tif` through GDAL (rasterio) and
rio-cogeo's Cloud-Optimized GeoTIFF validator (GDAL's validate_cloud_optimized_geotiff rules)."""

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
