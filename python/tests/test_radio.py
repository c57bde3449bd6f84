"""`trace` and `radio_map` against closed forms: free space (Friis) for the line of sight, the
mirror image for a ground reflection, on a Sionna RT scene file written here and on a run's
scene."""

import math
import struct
from pathlib import Path

import numpy as np
import pytest

import kodama_dag

C = 299_792_458.0
FREQ = 3.5e9
LAMBDA = C / FREQ


def friis(d):
    """Free-space path gain between isotropic antennas, linear."""
    return (LAMBDA / (4 * math.pi * d)) ** 2


@pytest.fixture(scope="module")
def plate(tmp_path_factory) -> Path:
    """A Sionna RT scene: one concrete ground square 200 m across at z = 0 (binary PLY)."""
    d = tmp_path_factory.mktemp("plate")
    (d / "meshes").mkdir()
    verts = [(-100.0, -100.0, 0.0), (100.0, -100.0, 0.0), (100.0, 100.0, 0.0), (-100.0, 100.0, 0.0)]
    faces = [(0, 1, 2), (0, 2, 3)]
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    body = b"".join(struct.pack("<3f", *v) for v in verts)
    body += b"".join(struct.pack("<B3i", 3, *f) for f in faces)
    (d / "meshes" / "ground.ply").write_bytes(header + body)
    (d / "scene.xml").write_text(
        '<scene version="2.1.0">\n'
        '  <bsdf type="itu-radio-material" id="itu_concrete">\n'
        '    <string name="type" value="concrete"/>\n'
        '    <float name="thickness" value="0.2"/>\n'
        "  </bsdf>\n"
        '  <shape type="ply" id="mesh-ground">\n'
        '    <string name="filename" value="meshes/ground.ply"/>\n'
        '    <ref id="itu_concrete" name="bsdf"/>\n'
        "  </shape>\n"
        "</scene>\n"
    )
    return d / "scene.xml"


def test_the_line_of_sight_is_friis_and_the_ground_bounce_its_mirror_image(plate):
    tx, rx = (0.0, 0.0, 10.0), (100.0, 0.0, 2.0)
    paths = kodama_dag.trace(plate, [[*tx, *rx]], FREQ)
    assert len(paths) == 1 and paths.valid[0].sum() == 2
    d_los = math.dist(tx, rx)
    d_mirror = math.dist(tx, (rx[0], rx[1], -rx[2]))
    k_los = int(np.argmin(np.where(paths.valid[0], paths.tau[0], np.inf)))
    assert paths.tau[0, k_los] == pytest.approx(d_los / C, rel=1e-9)
    assert abs(paths.a[0, k_los]) ** 2 == pytest.approx(friis(d_los), rel=1e-6)
    assert (paths.interactions[0, k_los] == 0).all()
    k_ref = 1 - k_los
    assert paths.tau[0, k_ref] == pytest.approx(d_mirror / C, rel=1e-9)
    # Specular reflection (Sionna RT's code 1) where the mirror image's line meets the ground.
    assert paths.interactions[0, k_ref, 0] == 1
    x_spec = rx[0] * tx[2] / (tx[2] + rx[2])
    assert paths.vertices[0, k_ref, 0] == pytest.approx([x_spec, 0.0, 0.0], abs=1e-6)
    assert paths.triangles[0, k_ref, 0] >= 0 and paths.triangles[0, k_ref, 1] == -1
    # Concrete reflects less than all of the field at grazing incidence.
    assert 0 < abs(paths.a[0, k_ref]) ** 2 < friis(d_mirror)
    total = abs(paths.a[0, k_los]) ** 2 + abs(paths.a[0, k_ref]) ** 2
    assert paths.gain_db[0] == pytest.approx(10 * math.log10(total), abs=1e-9)
    a, tau = paths.cir()
    assert a.shape == tau.shape == (1, 2)


def test_links_as_a_table_and_switches(plate):
    table = {
        "tx_x": [0.0, 0.0], "tx_y": [0.0, 0.0], "tx_z": [10.0, 10.0],
        "rx_x": [50.0, 150.0], "rx_y": [0.0, 0.0], "rx_z": [2.0, 2.0],
    }
    los_only = kodama_dag.trace(plate, table, FREQ, reflection=False, transmission=False)
    for k, x in enumerate([50.0, 150.0]):
        d = math.dist((0, 0, 10), (x, 0, 2))
        assert los_only.gain_db[k] == pytest.approx(10 * math.log10(friis(d)), abs=1e-6)
    # Padded: one path each, -1 delays past it.
    assert los_only.a.shape[1] == 1


def test_a_runs_scene_traces_in_its_site_frame(tmp_path):
    small = Path(__file__).parent / "small.ron"
    run = kodama_dag.run(small, cache=tmp_path / "c", out=False, quiet=True, targets=["truth"])
    # Straight down from 200 m to 150 m above the town, line of sight only: free space.
    paths = kodama_dag.trace((run, "truth"), [[60.0, 50.0, 200.0, 60.0, 50.0, 150.0]], FREQ,
                             reflection=False, transmission=False)
    assert paths.gain_db[0] == pytest.approx(10 * math.log10(friis(50.0)), abs=1e-6)
    with pytest.raises(kodama_dag.UserError, match="not a Scene"):
        kodama_dag.trace((run, "city"), [[0, 0, 10, 1, 0, 10]], FREQ)


def test_the_radio_map_over_open_ground_is_friis(plate):
    rm = kodama_dag.radio_map(plate, (0.0, 0.0, 10.0), FREQ, cell_m=10.0, height_m=1.5,
                              reflection=False, transmission=False, rays=4_000_000)
    _, h, w = rm.path_gain.shape
    assert (h, w) == (20, 20)
    assert rm.cell_centers.shape == (20, 20, 3)
    # Rows run south to north, as Sionna RT's.
    assert rm.cell_centers[0, 0, 1] < rm.cell_centers[-1, 0, 1]
    d = np.linalg.norm(rm.cell_centers - np.array([0.0, 0.0, 10.0]), axis=-1)
    far = (d > 30) & (d < 95)
    err_db = 10 * np.log10(rm.path_gain[0][far]) - 10 * np.log10(friis(d[far]))
    assert np.median(np.abs(err_db)) < 0.5, np.median(np.abs(err_db))
    assert rm.path_gain_db.shape == (20, 20)


@pytest.mark.parametrize(
    "kwargs, says",
    [
        ({"freq_hz": float("nan")}, "freq_hz"),
        ({"freq_hz": -1.0}, "freq_hz"),
        ({"links": [[0, 0, 10, 1, 0]]}, "shape"),
        ({"links": [[0, 0, float("inf"), 1, 0, 2]]}, "non-finite"),
        ({"rays": 0}, "rays"),
        ({"max_depth": -1}, "max_depth"),
        ({"tx_antenna": "horn"}, "tx_antenna"),
        ({"scattering_coefficient": 2.0}, "scattering_coefficient"),
    ],
)
def test_bad_arguments_are_user_errors(plate, kwargs, says):
    args = {"links": [[0, 0, 10, 50, 0, 2]], "freq_hz": FREQ}
    args.update(kwargs)
    links, freq = args.pop("links"), args.pop("freq_hz")
    with pytest.raises(kodama_dag.UserError, match=says):
        kodama_dag.trace(plate, links, freq, **args)


def test_a_missing_scene_file_is_a_user_error(tmp_path):
    with pytest.raises(kodama_dag.UserError, match="nowhere.xml"):
        kodama_dag.trace(tmp_path / "nowhere.xml", [[0, 0, 10, 50, 0, 2]], FREQ)


def test_a_runs_scene_exported_for_sionna_traces_as_the_run_does(tmp_path):
    import json

    small = Path(__file__).parent / "small.ron"
    run = kodama_dag.run(small, cache=tmp_path / "c", out=False, quiet=True, targets=["truth"])
    folder = run.export("truth", tmp_path / "truth.sionna")
    assert (folder / "scene.xml").is_file() and any((folder / "meshes").iterdir())
    site = json.loads((folder / "site.json").read_text())
    assert site["crs"] == run.crs and tuple(site["origin"]) == run.origin
    # A link over the town that meets the roofs and walls: the same paths from the file as from
    # the run's scene (the file keeps each material's slab thickness, as the scene does).
    links = [[20.0, 20.0, 30.0, 100.0, 80.0, 1.5], [60.0, 50.0, 40.0, 10.0, 90.0, 1.5]]
    from_run = kodama_dag.trace((run, "truth"), links, FREQ)
    from_file = kodama_dag.trace(folder / "scene.xml", links, FREQ)
    assert np.allclose(from_run.gain_db, from_file.gain_db, atol=1e-3), (
        from_run.gain_db, from_file.gain_db)
    assert (from_run.valid.sum(axis=1) == from_file.valid.sum(axis=1)).all()


def test_export_never_overwrites_a_folder(tmp_path):
    small = Path(__file__).parent / "small.ron"
    run = kodama_dag.run(small, cache=tmp_path / "c", out=False, quiet=True, targets=["dsm"])
    tif = run.export("dsm", tmp_path / "dsm.tif")
    assert tif.is_file()
    with pytest.raises(kodama_dag.UserError, match="already exists"):
        run.export("dsm", tif)
    run.export("dsm", tif, overwrite=True)
    keep = tmp_path / "mine.tif"
    keep.mkdir()
    (keep / "precious.txt").write_text("mine")
    with pytest.raises(kodama_dag.UserError, match="already exists"):
        run.export("dsm", keep, overwrite=True)
    assert (keep / "precious.txt").read_text() == "mine"
    with pytest.raises(kodama_dag.UserError, match="not .glb|written as"):
        run.export("dsm", tmp_path / "dsm.glb")
