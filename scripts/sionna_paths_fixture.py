"""Path gains computed by Sionna RT for links in two of its own scenes (munich,
simple_street_canyon): the reference our tracer is checked against (tests/sionna_crosscheck.rs).

    python3 scripts/sionna_paths_fixture.py ../shared/data/sionna-scenes tests/fixtures/sionna_paths.csv
    python3 scripts/sionna_paths_fixture.py ../shared/data/sionna-scenes \
        tests/fixtures/sionna_paths_refraction.csv --refraction
    python3 scripts/sionna_paths_fixture.py ../shared/data/sionna-scenes \
        tests/fixtures/sionna_paths_depth5.csv --depth 5
    python3 scripts/sionna_paths_fixture.py ../shared/data/sionna-scenes \
        tests/fixtures/sionna_paths_diffraction.csv --diffraction

One isotropic, vertically polarised transmitter per scene; receivers at 1.5 m drawn at random
(seeded) within 150 m (munich) or 120 m (street canyon) of it, kept only outdoors (nothing above them). Interactions: line of sight
and specular reflection to depth 3, no transmission, no diffuse reflection, no diffraction; 10^6
rays. With --refraction, the same receivers with transmission (refraction) through every surface
as well; with --depth N, specular reflection to depth N instead of 3; with --diffraction, wedge
diffraction too (Sionna's `diffraction=True`, its lit region included, no free edges). Path gain = 10 log10 sum |a|^2 (incoherent), as in Sionna's tutorials. Needs sionna-rt 2.2
and libLLVM 19 (scripts/sionna_env.py)."""
import csv
import sys

import sionna_env  # noqa: F401
import drjit as dr
import mitsuba as mi
import numpy as np
import sionna.rt
from sionna.rt import PathSolver, PlanarArray, Receiver, Transmitter, load_scene

SCENES = {
    "munich": ("munich/munich.xml", [8.5, 21.0, 27.0], 80, 150.0),
    "simple_street_canyon": ("simple_street_canyon/simple_street_canyon.xml", [-33.0, 0.0, 32.0], 50, 120.0),
}
FREQ = 3.5e9
DEPTH = 3


def outdoor(scene, p):
    ray = mi.Ray3f(o=mi.Point3f(float(p[0]), float(p[1]), float(p[2])), d=mi.Vector3f(0.0, 0.0, 1.0))
    return not bool(scene.mi_scene.ray_intersect(ray).is_valid()[0])


def link_gains(paths, n_rx):
    """Per receiver of a one-transmitter, one-antenna trace: the path gain 10 log10 sum |a|^2 as
    the fixture writes it ("-inf" without paths) and the number of paths."""
    a_re, a_im = paths.a
    a = a_re.numpy() + 1j * a_im.numpy()  # [rx, rx_ant, tx, tx_ant, paths]
    valid = paths.valid.numpy()
    out = []
    for i in range(n_rx):
        ai = a[i, 0, 0, 0][valid[i, 0]] if valid.ndim == 3 else a[i, 0, 0, 0]
        g = np.sum(np.abs(ai) ** 2)
        out.append((f"{10 * np.log10(g):.4f}" if g > 0 else "-inf",
                    int(np.count_nonzero(np.abs(ai) > 0))))
    return out


def main(root, out, refraction=False, depth=DEPTH, diffraction=False):
    rng = np.random.default_rng(2026)
    rows = []
    for name, (rel, tx, n_rx, reach) in SCENES.items():
        scene = load_scene(f"{root}/{rel}", merge_shapes=False)
        scene.frequency = FREQ
        scene.tx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
        scene.rx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
        scene.add(Transmitter(name="tx", position=tx))
        rxs = []
        while len(rxs) < n_rx:
            r = rng.uniform(20.0, reach)
            a = rng.uniform(0.0, 2 * np.pi)
            p = [float(tx[0] + r * np.cos(a)), float(tx[1] + r * np.sin(a)), 1.5]
            if outdoor(scene, p):
                rxs.append(p)
        for i, p in enumerate(rxs):
            scene.add(Receiver(name=f"rx{i}", position=p))
        paths = PathSolver()(scene, max_depth=depth, samples_per_src=10**6, los=True,
                             specular_reflection=True, diffuse_reflection=False,
                             refraction=refraction, diffraction=diffraction,
                             synthetic_array=True)
        for p, (gain, n) in zip(rxs, link_gains(paths, len(rxs))):
            rows.append([name, *tx, *p, FREQ, depth, gain, n])
        print(f"{name}: {len(rxs)} links")
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "tx_x", "tx_y", "tx_z", "rx_x", "rx_y", "rx_z", "freq_hz",
                    "max_depth", "path_gain_db", "num_paths"])
        w.writerows(rows)


if __name__ == "__main__":
    flags = sys.argv[3:]
    depth = int(flags[flags.index("--depth") + 1]) if "--depth" in flags else DEPTH
    main(sys.argv[1], sys.argv[2], refraction="--refraction" in flags, depth=depth,
         diffraction="--diffraction" in flags)
