"""The Python package against independent references: the point cloud re-rasterized in NumPy,
the site's numbers, the file the same run exported, and the CLI's error messages."""

import os
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

import kodama_dag

HERE = Path(__file__).parent
SMALL = HERE / "small.ron"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="module")
def small(cache, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    return kodama_dag.run(SMALL, cache=cache, out=out, quiet=True), out


def test_a_run_reports_every_node(small):
    run, out = small
    ids = [r.id for r in run.records]
    assert ids == ["city", "truth", "footprints", "lidar", "dsm", "dsm_stats"]
    assert all(r.status == "ran" for r in run.records)
    assert all(r.digest is not None and len(r.digest) == 64 for r in run.records)
    assert run.crs == "EPSG:32618" and run.origin == (583200.0, 4506600.0)
    assert Path(run.outputs["dsm.tif"]).is_file()


def test_a_second_run_is_all_cache_hits(small, cache):
    first, _ = small
    again = kodama_dag.run(SMALL, cache=cache, out=False, quiet=True)
    assert all(r.status == "cached" for r in again.records)
    assert [r.digest for r in again.records] == [r.digest for r in first.records]


def test_the_dsm_is_the_point_clouds_highest_return_per_cell(small):
    run, _ = small
    data, transform = run.raster("dsm", xarray=False)
    pts = run.points("lidar")
    xyz = pts["xyz"].astype(np.float64)
    assert xyz.shape[1] == 3 and xyz.shape[0] > 10_000
    # The raster's cells in the site frame, from its geotransform in the CRS.
    x0 = transform[0] - run.origin[0]
    y0 = transform[3] - run.origin[1]
    cell = transform[1]
    col = np.floor((xyz[:, 0] - x0) / cell).astype(np.int64)
    row = np.floor((y0 - xyz[:, 1]) / cell).astype(np.int64)
    h, w = data.shape
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    top = np.full((h, w), -np.inf)
    np.maximum.at(top, (row[inside], col[inside]), xyz[inside, 2])
    hit = np.isfinite(top)
    assert hit.mean() > 0.5
    assert np.allclose(data[hit], top[hit], atol=1e-3)


def test_arrays_are_the_artifacts_own_buffers(small):
    run, _ = small
    data, _ = run.raster("dsm", xarray=False)
    assert data.dtype == np.float32 and not data.flags.owndata
    xyz = run.points("lidar")["xyz"]
    assert xyz.dtype == np.float32 and not xyz.flags.owndata and xyz.flags.c_contiguous


def test_the_metrics_agree_with_the_raster(small):
    run, _ = small
    stats = run.metrics("dsm_stats")
    data, _ = run.raster("dsm", xarray=False)
    finite = data[np.isfinite(data)]
    assert stats, "RasterStats made no metrics"
    for key, value in stats.items():
        if key.endswith("max"):
            assert value == pytest.approx(float(finite.max()), abs=1e-3)
        if key.endswith("min"):
            assert value == pytest.approx(float(finite.min()), abs=1e-3)


def test_the_exported_geotiff_holds_the_same_numbers(small):
    run, _ = small
    data, transform = run.raster("dsm", xarray=False)
    tif = Path(run.outputs["dsm.tif"])
    try:
        from PIL import Image
    except ImportError:
        if os.environ.get("CI") == "true":
            raise
        pytest.skip("Pillow is not installed: the GeoTIFF comparison needs it")
    with Image.open(tif) as im:
        read = np.array(im, dtype=np.float32)
    assert read.shape == data.shape
    assert np.array_equal(np.isnan(read), np.isnan(data))
    assert np.array_equal(read[~np.isnan(read)], data[~np.isnan(data)])


def test_footprints_lie_on_the_site_in_its_crs(small):
    run, _ = small
    fps = run.footprints("footprints")
    if isinstance(fps, dict):
        features = fps["features"]
        coords = np.array(
            [p for f in features for p in f["geometry"]["coordinates"][0]], dtype=np.float64
        )
    else:
        features = list(fps.geometry)
        coords = np.concatenate([np.asarray(g.exterior.coords) for g in fps.geometry])
    assert len(features) >= 4
    ox, oy = run.origin
    assert (coords[:, 0] > ox).all() and (coords[:, 0] < ox + 120.0).all()
    assert (coords[:, 1] > oy).all() and (coords[:, 1] < oy + 100.0).all()


def test_a_scene_is_meshes_with_named_materials(small):
    run, _ = small
    objects = run.scene("truth")
    classes = {o["class"] for o in objects}
    assert "Terrain" in classes and "Building" in classes
    for o in objects:
        v, t, m = o["vertices"], o["triangles"], o["materials"]
        assert v.shape[1] == 3 and t.shape[1] == 3 and m.shape == (t.shape[0],)
        assert t.max() < v.shape[0]
        assert all(int(k) in o["material_names"] for k in np.unique(m))
    assert "concrete" in objects[0]["material_names"].values()


def test_explain_after_a_run_says_cached(small, cache):
    plan = kodama_dag.explain(SMALL, cache=cache)
    assert [p.plan for p in plan] == ["cached"] * 6
    changed = kodama_dag.explain(SMALL, cache=cache, set={"lidar.density_per_m2": 5.0})
    by_id = {p.id: p.plan for p in changed}
    assert by_id["city"] == "cached" and by_id["lidar"] == "run" and by_id["dsm"] != "cached"


def test_kinds_name_their_inputs_and_outputs():
    k = kodama_dag.kinds()
    assert k["RasterizeSurface"].output == "Raster"
    assert k["RasterizeSurface"].inputs[0][:3] == ("points", "Points", "one")
    assert len(k) > 50


def test_kinds_give_every_param_with_its_default_and_doc():
    m = kodama_dag.kinds()["RadioMap"]
    params = {p.name: p for p in m.params}
    assert params["tx"].required and params["tx"].type == "(f64, f64, f64)"
    assert "above the terrain" in params["tx"].doc
    assert params["cell_m"].default == 5.0 and not params["cell_m"].required
    assert params["options"].default["max_depth"] == 3
    assert params["antenna"].default["pattern"] == "Isotropic"
    assert "struct MapOptions:" in m.reference and "clockwise from grid north" in m.reference


def test_a_bad_graph_is_a_user_error_naming_file_and_place(tmp_path, cache):
    bad = tmp_path / "bad.ron"
    bad.write_text(SMALL.read_text().replace('"city": SynthCity', '"city": SynthCty', 1).replace('"city":       SynthCity', '"city":       SynthCty'))
    with pytest.raises(kodama_dag.UserError) as e:
        kodama_dag.run(bad, cache=cache, out=False, quiet=True)
    msg = str(e.value)
    assert "bad.ron" in msg and "SynthCty" in msg and "SynthCity" in msg


@pytest.mark.parametrize(
    "kwargs, says",
    [
        ({"set": {"lidar.density_per_m2": float("nan")}}, "finite"),
        ({"set": {"lidar.no_such_param": 1}}, "no_such_param"),
        ({"set": {"nodot": 1}}, "node.param"),
        ({"targets": ["nowhere"]}, "nowhere"),
        ({"tile_m": float("inf")}, "tile_m"),
        ({"jobs": 0}, "jobs"),
    ],
)
def test_bad_arguments_are_user_errors(kwargs, says, cache):
    with pytest.raises(kodama_dag.UserError) as e:
        kodama_dag.run(SMALL, cache=cache, out=False, quiet=True, **kwargs)
    assert says in str(e.value)


def test_a_folder_that_is_not_a_cache_is_refused_and_left_alone(tmp_path):
    # As the CLI: a folder becomes a cache unless its cas/, ac/ or tmp/ hold what the engine
    # did not write; such a folder is refused and not written to.
    notes = tmp_path / "notes"
    (notes / "cas").mkdir(parents=True)
    (notes / "cas" / "thesis.txt").write_text("mine")
    with pytest.raises(kodama_dag.UserError, match="not a cache|no FORMAT"):
        kodama_dag.run(SMALL, cache=notes, out=False, quiet=True)
    assert sorted(str(p.relative_to(notes)) for p in notes.rglob("*")) == ["cas", "cas/thesis.txt"]


def test_reading_the_wrong_type_says_what_the_node_makes(small):
    run, _ = small
    with pytest.raises(TypeError, match="Points"):
        run.raster("lidar")
    with pytest.raises(KeyError, match="nowhere"):
        run.raster("nowhere")


def test_other_threads_run_while_a_graph_runs(cache, tmp_path):
    # The GIL is released for the run: a Python thread counts meanwhile.
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(1)
            stop.wait(0.001)

    t = threading.Thread(target=count)
    t.start()
    try:
        kodama_dag.run(SMALL, cache=tmp_path / "fresh", out=False, quiet=True)
    finally:
        stop.set()
        t.join()
    assert len(ticks) > 10


def test_rasters_as_dataarrays_carry_crs_coordinates(small):
    xr = pytest.importorskip("xarray") if os.environ.get("CI") != "true" else __import__("xarray")
    run, _ = small
    da = run.raster("dsm")
    data, transform = run.raster("dsm", xarray=False)
    assert isinstance(da, xr.DataArray) and da.dims == ("y", "x")
    assert da.x.values[0] == pytest.approx(transform[0] + transform[1] / 2)
    assert da.y.values[0] == pytest.approx(transform[3] + transform[5] / 2)
    assert da.attrs["crs"] == "EPSG:32618"
    assert np.shares_memory(da.values, data) or np.array_equal(da.values, data, equal_nan=True)


SWEEP = HERE / "small_sweep.ron"


@pytest.fixture(scope="module")
def swept(cache, tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    return kodama_dag.sweep(SWEEP, cache=cache, out=out, quiet=True), out


def test_a_sweeps_table_is_the_csv_the_engine_wrote(swept):
    import csv

    result, out = swept
    table = result.table(pandas=False)
    assert result.variants == [
        "density=4.0,rule=max",
        "density=4.0,rule=min",
        "density=2.0,rule=max",
        "density=2.0,rule=min",
    ]
    assert table["density"] == ["4.0", "4.0", "2.0", "2.0"]
    with open(out / "table.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4
    for k, row in enumerate(rows):
        for m in ["dsm_stats.max", "dsm_stats.mean"]:
            assert table[m][k] == pytest.approx(float(row[m]), rel=1e-6)
    assert list(table) == ["variant", "density", "rule", "dsm_stats.max", "dsm_stats.mean"]


def test_each_variant_reads_as_a_run(swept):
    result, _ = swept
    mx = result.run("density=2.0,rule=max").metrics("dsm_stats")
    mn = result.run("density=2.0,rule=min").metrics("dsm_stats")
    # The lowest return per cell is never above the highest.
    assert mn["mean"] < mx["mean"]
    data, _ = result.run(0).raster("dsm", xarray=False)
    assert float(np.nanmax(data)) == pytest.approx(result.table(pandas=False)["dsm_stats.max"][0], abs=1e-3)
    with pytest.raises(KeyError, match="no variant"):
        result.run("density=3.0,rule=max")


def test_a_second_sweep_is_all_cache_hits(swept, cache, tmp_path):
    again = kodama_dag.sweep(SWEEP, cache=cache, out=tmp_path, quiet=True)
    for k in range(len(again.variants)):
        assert all(r.status == "cached" for r in again.run(k).records)


def test_a_bad_sweep_is_a_user_error(tmp_path, cache):
    bad = tmp_path / "bad_sweep.ron"
    bad.write_text('Sweep(graph: "nowhere.ron", axes: {}, metrics: [])')
    with pytest.raises(kodama_dag.UserError, match="bad_sweep.ron|nowhere.ron"):
        kodama_dag.sweep(bad, cache=cache, out=tmp_path / "o", allow_outside=True)


@pytest.mark.parametrize("node, shape", [
    ("one", (1, 1)), ("small", (3, 5)), ("medium", (100, 100)), ("large", (300, 300)),
])
def test_raster_cells_are_read_in_place_whatever_their_header(cache, node, shape):
    run = kodama_dag.run(HERE / "rasters.ron", cache=cache, out=False, quiet=True)
    data, _ = run.raster(node, xarray=False)
    assert data.shape == shape and data.dtype == np.float32
    # A view of the cache's file: not NumPy's memory, and not writable (the mapping is not).
    assert not data.flags.owndata and not data.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        data[0, 0] = 0.0
    # The engine's statistics of the same raster: an offset by a byte would scramble them.
    stats = run.metrics(f"{node}_stats")
    assert float(data.min()) == pytest.approx(stats["min"], abs=1e-4)
    assert float(data.max()) == pytest.approx(stats["max"], abs=1e-4)
    assert float(data.mean(dtype=np.float64)) == pytest.approx(stats["mean"], abs=1e-4)


def test_links_carry_wgs84_ends_as_the_exported_csv_does(tmp_path):
    import csv

    run = kodama_dag.run(HERE / "quickstart.ron", cache=tmp_path / "c", out=False, quiet=True,
                         targets=["drive_test"])
    # The UTM 18N textbook point: lon -75, lat 40 is E 500000, N 4427757.22 m.
    lon, lat = run.lon_lat([500_000.0 - run.origin[0]], [4_427_757.22 - run.origin[1]])
    assert lon[0] == pytest.approx(-75.0, abs=1e-7) and lat[0] == pytest.approx(40.0, abs=1e-6)
    links = run.links("drive_test")
    csv_path = run.export("drive_test", tmp_path / "drive.csv")
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(links["rx_lat"]) > 10
    for k in (0, len(rows) - 1):
        for col in ("tx_lon", "tx_lat", "rx_lon", "rx_lat"):
            assert float(rows[k][col]) == pytest.approx(float(links[col][k]), abs=1e-8)
    assert 40.6 < float(links["rx_lat"][0]) < 40.8 and -74.1 < float(links["rx_lon"][0]) < -73.9


def test_progress_goes_through_sys_stderr_where_a_notebook_shows_it(tmp_path, capsys):
    """Jupyter shows what is written to `sys.stderr` under the cell, not the process's fd 2: a
    run's lines go through it (capsys sees only Python-level writes)."""
    kodama_dag.run(HERE / "small.ron", cache=tmp_path / "c", out=False)
    err = capsys.readouterr().err
    assert "running  city (SynthCity)" in err, err
    assert "ran      dsm (RasterizeSurface)" in err, err
    assert "nodes: 6 ran, 0 cached" in err, err
    # A stage that counts its work has a line per tenth of it, in order.
    tenths = [line for line in err.splitlines() if line.rstrip().endswith("%")]
    for stage in {line.split(")")[0] for line in tenths}:
        pcts = [int(l.rsplit(" ", 1)[1][:-1]) for l in tenths if l.startswith(stage + ")")]
        assert pcts == sorted(pcts) and pcts[-1] == 100, (stage, pcts)

    kodama_dag.run(HERE / "small.ron", cache=tmp_path / "c", out=False, quiet=True)
    assert capsys.readouterr().err == ""
