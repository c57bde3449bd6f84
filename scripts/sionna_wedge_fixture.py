"""First-order edge diffraction by Sionna RT around one closed box: the reference for the UTD
wedge test in tests/sionna_crosscheck.rs (path_gains_over_one_box_match_sionna_rt).

    python3 scripts/sionna_wedge_fixture.py tests/fixtures/sionna_wedge.csv

The box: x in [0, 20], y in [0, 20], z in [0, 30] metres, one ITU material per run (marble,
metal), written as PLY + Mitsuba XML into a temporary folder. Two transmitters beside it; 36
receivers on a circle of 35 m around the box's axis at 1.5 m and 36 at 12 m: lit, grazing and
deep-shadow geometries over its vertical corners and its roof edges. Only diffraction (no line
of sight, no reflection, no transmission), max_depth 1, 10^6 rays, 3.5 GHz, isotropic V
antennas. Path gain = 10 log10 sum |a|^2. Needs sionna-rt 2.2 and libLLVM 19
(scripts/sionna_env.py)."""
import csv
import os
import struct
import sys
import tempfile

import sionna_env  # noqa: F401
import numpy as np
from sionna.rt import PathSolver, PlanarArray, Receiver, Transmitter, load_scene

from sionna_paths_fixture import link_gains

FREQ = 3.5e9
BOX = (0.0, 20.0, 0.0, 20.0, 0.0, 30.0)
TXS = [(40.0, 30.0, 20.0), (30.0, -10.0, 40.0)]
MATERIALS = {"marble": 0.03, "metal": 0.002}


def write_ply(path, v, f):
    """Binary little-endian PLY of float vertices `v` and triangles `f`."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    with open(path, "wb") as out:
        out.write(head.encode())
        out.write(b"".join(struct.pack("<3f", *p) for p in v))
        out.write(b"".join(struct.pack("<B3i", 3, *t) for t in f))


def box_ply(path):
    x0, x1, y0, y1, z0, z1 = BOX
    v = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    f = [(0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6), (0, 1, 5), (0, 5, 4),
         (2, 6, 7), (2, 7, 3), (0, 4, 6), (0, 6, 2), (1, 3, 7), (1, 7, 5)]
    write_ply(path, v, f)


def scene_xml(folder, material, thickness):
    os.makedirs(f"{folder}/meshes", exist_ok=True)
    box_ply(f"{folder}/meshes/box.ply")
    with open(f"{folder}/scene.xml", "w") as out:
        out.write(f"""<scene version="2.1.0">
<bsdf type="itu-radio-material" id="itu_{material}">
  <string name="type" value="{material}"/><float name="thickness" value="{thickness}"/>
</bsdf>
<shape type="ply" id="mesh-box">
  <string name="filename" value="meshes/box.ply"/><boolean name="face_normals" value="true"/>
  <ref id="itu_{material}" name="bsdf"/>
</shape>
</scene>
""")
    return f"{folder}/scene.xml"


def box_scene(folder, material, thickness, tx):
    """The box in `material`, loaded by Sionna at FREQ, isotropic V arrays, the transmitter at
    `tx`."""
    scene = load_scene(scene_xml(folder, material, thickness), merge_shapes=False)
    scene.frequency = FREQ
    scene.tx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.rx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    scene.add(Transmitter(name="tx", position=list(tx)))
    return scene


def receivers():
    cx, cy = (BOX[0] + BOX[1]) / 2, (BOX[2] + BOX[3]) / 2
    out = []
    for z in (1.5, 12.0):
        for k in range(36):
            a = 2 * np.pi * (k + 0.5) / 36
            out.append((cx + 35.0 * np.cos(a), cy + 35.0 * np.sin(a), z))
    return out


def main(out_path):
    rows = []
    rxs = receivers()
    with tempfile.TemporaryDirectory() as tmp:
        for material, thickness in MATERIALS.items():
            for t, tx in enumerate(TXS):
                scene = box_scene(f"{tmp}/{material}", material, thickness, tx)
                for i, p in enumerate(rxs):
                    scene.add(Receiver(name=f"rx{i}", position=[float(c) for c in p]))
                paths = PathSolver()(scene, max_depth=1, samples_per_src=10**6, los=False,
                                     specular_reflection=False, diffuse_reflection=False,
                                     refraction=False, diffraction=True, synthetic_array=True)
                for p, (gain, n) in zip(rxs, link_gains(paths, len(rxs))):
                    rows.append([material, *tx, *(f"{c:.6f}" for c in p), FREQ, gain, n])
                print(f"{material}, tx {t}: {len(rxs)} links")
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["material", "tx_x", "tx_y", "tx_z", "rx_x", "rx_y", "rx_z", "freq_hz",
                    "path_gain_db", "num_paths"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1])
