"""Edge diffraction by a perfectly conducting wedge: the exact solution, and Sionna RT beside it.
The reference for tests/sionna_crosscheck.rs (diffraction_by_a_conducting_wedge_against_the_exact_solution).

    python3 scripts/pec_wedge_fixture.py tests/fixtures/pec_wedge.csv

Neither tracer is the reference here. For a line source beside an infinite perfectly conducting
wedge the field is known exactly as a series of wedge eigenfunctions (Bowman, Senior and
Uslenghi, "Electromagnetic and Acoustic Scattering by Simple Shapes", ch. 6): with the faces at
phi = 0 and phi = alpha = n pi, nu_m = m pi / alpha,

    u = -(j pi / alpha) sum_m eps_m J_nu(k rho_<) H2_nu(k rho_>) f(nu phi) f(nu phi'),

f = sin (E parallel to the edge: soft, m >= 1) or cos (E across it: hard, m >= 0, eps_0 = 1/2),
normalised so that free space would give -(j/4) H2_0(k R). Taking the geometrical-optics field
(incident and face-reflected waves where they exist) from the series leaves the diffracted
field, and dividing it by the incident field at the edge and the cylindrical spreading
e^{-jk rho}/sqrt(rho) leaves the exact diffraction coefficient D(phi, phi'). A point source at
the same distances, square to the edge, diffracts with that coefficient and spherical spreading:
path gain (lambda / 4 pi)^2 |D|^2 / (s s' (s + s')). That is `exact_db`.

The same geometry traced by Sionna RT 2.2 (PathSolver, diffraction alone, max_depth 1, 10^6
samples, isotropic antennas) is `sionna_db`: the wedge a closed metal prism 600 m tall whose
faces run 400 m from the edge, the edge along z through the origin, face 0 along -y. Two wedges
(a building's corner, n = 1.5, and an acute 45 degree one, n = 1.75), two source angles each
(one lighting both faces, one only face 0), both polarisations, 3.5 GHz, source at 30 m,
receivers at 20 m. Needs scipy, sionna-rt 2.2 and libLLVM 19 (scripts/sionna_env.py)."""
import csv
import os
import sys
import tempfile

import sionna_env  # noqa: F401
import numpy as np
from scipy.special import hankel2, jv
from sionna.rt import PathSolver, PlanarArray, Receiver, Transmitter, load_scene

from sionna_paths_fixture import link_gains
from sionna_wedge_fixture import write_ply

FREQ = 3.5e9
WAVELENGTH = 299792458.0 / FREQ
K = 2 * np.pi / WAVELENGTH
RHO_TX, RHO_RX = 30.0, 20.0
REACH, HALF_HEIGHT = 400.0, 300.0
WEDGES = {1.5: (0.3, 0.8), 1.75: (0.3, 0.8)}  # n: source angles phi' / pi
RECEIVERS = 25


def line_source(r):
    """Free-space field of the unit line source at distance r: -(j/4) H2_0(k r)."""
    return -0.25j * hankel2(0, K * r)


def exact_field(n, rho_s, phi_s, rho, phi, hard):
    """The eigenfunction series: the total field at (rho, phi) of a line source at
    (rho_s, phi_s) beside the wedge whose faces are phi = 0 and phi = n pi."""
    alpha = n * np.pi
    lo, hi = min(rho, rho_s), max(rho, rho_s)
    # J_nu(k lo) dies off past nu ~ k lo: a few hundred orders beyond it are ample.
    m = np.arange(0 if hard else 1, int(K * lo * n) + 400)
    nu = m * np.pi / alpha
    radial = jv(nu, K * lo) * hankel2(nu, K * hi)
    if hard:
        ang = np.cos(nu * phi) * np.cos(nu * phi_s) * np.where(m == 0, 0.5, 1.0)
    else:
        ang = np.sin(nu * phi) * np.sin(nu * phi_s)
    return (-1j * np.pi / alpha) * np.sum(radial * ang)


def geometrical_optics(n, rho_s, phi_s, rho, phi, hard):
    """Incident and face-reflected line-source waves where they exist (images across each face;
    a perfect conductor reflects the soft field with -1, the hard with +1)."""
    pos = lambda r, a: r * np.array([np.cos(a), np.sin(a)])
    obs = pos(rho, phi)
    sign = 1.0 if hard else -1.0
    u = 0j
    if abs(phi - phi_s) < np.pi:
        u += line_source(np.linalg.norm(obs - pos(rho_s, phi_s)))
    if phi < np.pi - phi_s:
        u += sign * line_source(np.linalg.norm(obs - pos(rho_s, -phi_s)))
    if phi > (2 * n - 1) * np.pi - phi_s:
        u += sign * line_source(np.linalg.norm(obs - pos(rho_s, 2 * n * np.pi - phi_s)))
    return u


def exact_coefficient(n, phi_s, phi, hard):
    """D(phi, phi') of the exact solution: its diffracted field over the incident field at the
    edge and the cylindrical spreading."""
    u_d = exact_field(n, RHO_TX, phi_s, RHO_RX, phi, hard) \
        - geometrical_optics(n, RHO_TX, phi_s, RHO_RX, phi, hard)
    return u_d / (line_source(RHO_TX) * np.exp(-1j * K * RHO_RX) / np.sqrt(RHO_RX))


def exact_db(d):
    s, s_prime = RHO_RX, RHO_TX
    return 10 * np.log10((WAVELENGTH / (4 * np.pi)) ** 2 * abs(d) ** 2
                         / (s * s_prime * (s + s_prime)))


def world(rho, phi, z=0.0):
    """Wedge coordinates to the world: face 0 along -y, the edge the z axis. Rounded to the nm:
    cos(pi) of 1e-16 off zero would tilt a face of the prism (and Sionna then finds no
    diffraction behind it)."""
    return (round(float(rho * np.cos(phi - np.pi / 2)), 9),
            round(float(rho * np.sin(phi - np.pi / 2)), 9), z)


def receiver_angles(n, phi_s, margin=0.01):
    """RECEIVERS angles across the open region, none within `margin` pi of a shadow boundary
    (where geometrical optics jumps and its subtraction is not defined)."""
    bounds = [phi_s + np.pi, phi_s - np.pi, np.pi - phi_s, (2 * n - 1) * np.pi - phi_s]
    out = []
    for a in np.linspace(0.03 * np.pi, (n - 0.03) * np.pi, RECEIVERS):
        while min(abs(a - b) for b in bounds) < margin * np.pi:
            a += 0.01 * np.pi
        out.append(a)
    return out


def prism_ply(path, n):
    """The wedge as a closed prism: the triangle (edge, REACH along face 0, REACH along face n)."""
    tri = [(0.0, 0.0), world(REACH, 0.0)[:2], world(REACH, n * np.pi)[:2]]
    v = [(x, y, z) for z in (-HALF_HEIGHT, HALF_HEIGHT) for x, y in tri]
    # Outward normals: the triangle runs clockwise seen from +z (face n, then face 0, CCW
    # from inside the solid), so the bottom keeps its order and the top reverses it.
    f = [(0, 1, 2), (3, 5, 4), (0, 3, 4), (0, 4, 1), (1, 4, 5), (1, 5, 2), (2, 5, 3), (2, 3, 0)]
    write_ply(path, v, f)


def sionna_gains(folder, n, tx, rxs, pol, material="metal", thickness=0.002):
    """Sionna RT's path gains (dB) of the links tx -> rxs over the prism wedge of `n` made of
    the ITU `material` as a slab `thickness` metres thick."""
    os.makedirs(f"{folder}/meshes", exist_ok=True)
    prism_ply(f"{folder}/meshes/wedge.ply", n)
    with open(f"{folder}/scene.xml", "w") as out:
        out.write(f"""<scene version="2.1.0">
<bsdf type="itu-radio-material" id="itu_{material}">
  <string name="type" value="{material}"/><float name="thickness" value="{thickness}"/>
</bsdf>
<shape type="ply" id="mesh-wedge">
  <string name="filename" value="meshes/wedge.ply"/><boolean name="face_normals" value="true"/>
  <ref id="itu_{material}" name="bsdf"/>
</shape>
</scene>
""")
    scene = load_scene(f"{folder}/scene.xml", merge_shapes=False)
    scene.frequency = FREQ
    scene.tx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization=pol)
    scene.rx_array = PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization=pol)
    scene.add(Transmitter(name="tx", position=list(tx)))
    for i, p in enumerate(rxs):
        scene.add(Receiver(name=f"rx{i}", position=list(p)))
    paths = PathSolver()(scene, max_depth=1, samples_per_src=10**6, los=False,
                         specular_reflection=False, diffuse_reflection=False,
                         refraction=False, diffraction=True, synthetic_array=True)
    return [g for g, _ in link_gains(paths, len(rxs))]


def main(out_path):
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, sources in WEDGES.items():
            for phi_s_pi in sources:
                phi_s = phi_s_pi * np.pi
                tx = world(RHO_TX, phi_s)
                angles = receiver_angles(n, phi_s)
                rxs = [world(RHO_RX, a) for a in angles]
                for pol, hard in (("V", False), ("H", True)):
                    sionna = sionna_gains(f"{tmp}/{n}-{phi_s_pi}-{pol}", n, tx, rxs, pol)
                    for a, rx, s in zip(angles, rxs, sionna):
                        exact = exact_db(exact_coefficient(n, phi_s, a, hard))
                        rows.append([n, f"{phi_s_pi:.2f}", f"{a / np.pi:.6f}", pol,
                                     *(f"{c:.6f}" for c in tx), *(f"{c:.6f}" for c in rx),
                                     f"{exact:.4f}", s])
                    print(f"n {n}, phi' {phi_s_pi} pi, {pol}: {len(rxs)} receivers")
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["n", "phi_s_over_pi", "phi_over_pi", "polarization", "tx_x", "tx_y", "tx_z",
                    "rx_x", "rx_y", "rx_z", "exact_db", "sionna_db"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1])
