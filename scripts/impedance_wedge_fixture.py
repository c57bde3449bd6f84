"""Edge diffraction by a lossy wedge: Maliuzhinets' exact solution, and Sionna RT beside it.
The reference for tests/sionna_crosscheck.rs (diffraction_by_a_lossy_wedge_against_maliuzhinets).

    python3 scripts/impedance_wedge_fixture.py tests/fixtures/impedance_wedge.csv
    python3 scripts/impedance_wedge_fixture.py --development-set

Neither tracer is the reference here. A wedge whose faces obey the impedance (Leontovich)
boundary condition has an exact solution (Maliuzhinets 1958; Osipov and Norris, "The Malyuzhinets
theory for scattering from wedge boundaries: a review", Wave Motion 29, 1999). In the wedge's own
frame (the field fills |phi| < Phi = n pi / 2, the faces at phi = +-Phi) the field of a plane wave
from phi0 is a Sommerfeld integral of the spectrum

    s(a) = sigma(a) Psi(a) / Psi(phi0),  sigma(a) = mu cos(mu phi0) / (sin(mu a) - sin(mu phi0)),
    Psi(a) = psi(a + Phi + pi/2 - t+) psi(a + Phi - pi/2 + t+) psi(a - Phi - pi/2 + t-)
             psi(a - Phi + pi/2 - t-),                                       mu = pi / (2 Phi),

where sin t+- is each face's normalised admittance (E along the edge: sqrt(eps_r); across it:
1 / sqrt(eps_r), the Leontovich impedance of a half-space) and psi = psi_Phi is Maliuzhinets'
function, for |Re z| < 2 Phi + pi/2

    psi(z) = exp(-1/2 int_0^inf (cosh(z t) - 1) / (t cosh(pi t / 2) sinh(2 Phi t)) dt),

and beyond it psi(z + 2 Phi) = psi(z - 2 Phi) cot(z / 2 + pi / 4), psi(-z) = psi(z). The
steepest-descent evaluation of the integral gives the diffracted wave e^{-jk rho} / sqrt(rho)
with the coefficient

    D(phi, phi0) = (s(phi - pi) - s(phi + pi)) / sqrt(2 pi k)     (in magnitude),

the exact solution's far field (Keller's GTD coefficient of this wedge). Before writing anything
the script checks its reference: the functional equation of psi; the perfect-conductor limits
(sin t -> infinity, sin t = 0) against Keller's closed form; each face's reflection from the
residue against the impedance plane's (sin g - sin t) / (sin g + sin t); reciprocity; and no
diffraction by a flat face (Phi = pi / 2).

D is a far-field coefficient: it leaves out the transition function of the UTD, which tends to
1 away from the shadow boundaries. Receivers therefore keep MARGIN (0.06 pi) from every shadow
boundary, where for the conducting wedge of `pec_wedge_fixture.py` the same far-field coefficient
is within 0.06 dB of the eigenfunction series (k L a >= 15). A point source at s' with a receiver
at s, both square to the edge, diffracts with path gain (lambda / 4 pi)^2 |D|^2 / (s s' (s + s')):
`exact_db`.

The wedges are `pec_wedge_fixture.py`'s (n 1.5 and 1.75; the source lighting both faces or only
face 0; V and H; source at 30 m, receivers at 20 m; 3.5 GHz), made of ITU-R P.2040-3 wet ground
(eps_r = 18.3 - 3.9j at 3.5 GHz, where the Leontovich impedance is within 3 % of the half-space's
Fresnel coefficients at any incidence) and concrete (eps_r = 5.24 - 0.63j: within 11 %, so there
the reference's faces already differ from a half-space's), as slabs 2 m thick in both tracers
(reflecting as a half-space: a wave across them and back is attenuated by over 100 dB).
`luebbers_db` is Luebbers' heuristic with the reference's own impedance faces (what ours
computes, without the face model's difference) and `sionna_db` Sionna RT 2.2 (PathSolver,
diffraction alone, 10^6 samples). Needs scipy, sionna-rt 2.2 and libLLVM 19."""
import csv
import sys
import tempfile

import numpy as np
from scipy.integrate import quad

from pec_wedge_fixture import (RHO_RX, RHO_TX, WAVELENGTH, K, FREQ, WEDGES, exact_db,
                               receiver_angles, sionna_gains, world)

HALF_PI = np.pi / 2
MARGIN = 0.06
THICKNESS = 2.0
# ITU-R P.2040-3 Table 3: eps_r' = a f^b, sigma = c f^d (f in GHz).
MATERIALS = {"wet_ground": (30.0, -0.4, 0.15, 1.30), "concrete": (5.24, 0.0, 0.0462, 0.7822)}


def permittivity(material):
    return permittivity_of(MATERIALS[material])


def permittivity_of(law):
    a, b, c, d = law
    f_ghz = FREQ / 1e9
    sigma = c * f_ghz ** d
    return a * f_ghz ** b - 1j * sigma / (2 * np.pi * FREQ * 8.8541878128e-12)


def _log_psi_integrand(t, z, big_phi):
    """(cosh(z t) - 1) / (t cosh(pi t / 2) sinh(2 Phi t)), written so that neither the small-t
    difference nor the large-t exponentials lose precision."""
    a, b = HALF_PI, 2 * big_phi
    if t < 1.0:
        return 2 * np.sinh(z * t / 2) ** 2 / (t * np.cosh(a * t) * np.sinh(b * t))
    den = (1 + np.exp(-2 * a * t)) * (1 - np.exp(-2 * b * t)) * t
    return 2 * (np.exp((z - a - b) * t) + np.exp((-z - a - b) * t)
                - 2 * np.exp(-(a + b) * t)) / den


def psi(z, big_phi):
    """Maliuzhinets' function psi_Phi(z): the integral inside the strip, the functional equation
    and evenness outside it."""
    z = complex(z)
    if z.real < 0:
        z = -z
    if z.real > 2 * big_phi:
        return psi(z - 4 * big_phi, big_phi) / np.tan((z - 2 * big_phi) / 2 + np.pi / 4)
    top = 60 / (HALF_PI + 2 * big_phi - abs(z.real))  # the integrand is e^-60 smaller there
    part = lambda f: quad(f, 0, top, limit=800, epsabs=1e-14, epsrel=1e-12)[0]
    re = part(lambda t: _log_psi_integrand(t, z, big_phi).real)
    im = part(lambda t: _log_psi_integrand(t, z, big_phi).imag)
    return np.exp(-0.5 * (re + 1j * im))


def big_psi(a, big_phi, t_plus, t_minus):
    return (psi(a + big_phi + HALF_PI - t_plus, big_phi)
            * psi(a + big_phi - HALF_PI + t_plus, big_phi)
            * psi(a - big_phi - HALF_PI + t_minus, big_phi)
            * psi(a - big_phi + HALF_PI - t_minus, big_phi))


def spectrum(a, phi0, big_phi, t_plus, t_minus):
    mu = np.pi / (2 * big_phi)
    sigma = mu * np.cos(mu * phi0) / (np.sin(mu * a) - np.sin(mu * phi0))
    return sigma * big_psi(a, big_phi, t_plus, t_minus) / big_psi(phi0, big_phi, t_plus, t_minus)


def maliuzhinets_coefficient(n, phi_s, phi, sin_t):
    """D(phi, phi') of the impedance wedge with faces phi = 0 and n pi (both of normalised
    admittance sin_t), angles from face 0 as in pec_wedge_fixture.py."""
    big_phi = n * HALF_PI
    t = np.arcsin(complex(sin_t))
    s = lambda a: spectrum(a, phi_s - big_phi, big_phi, t, t)
    return (s(phi - big_phi - np.pi) - s(phi - big_phi + np.pi)) / np.sqrt(2 * np.pi * K)


def keller_coefficient(n, phi_s, phi, hard):
    """The perfectly conducting wedge's GTD coefficient (Keller)."""
    cot = lambda b: 1 / (np.cos(np.pi / n) - np.cos(b / n))
    sign = 1 if hard else -1
    return np.sin(np.pi / n) / (n * np.sqrt(2 * np.pi * K)) \
        * (cot(phi - phi_s) + sign * cot(phi + phi_s))


def impedance_reflection(grazing, sin_t):
    return (np.sin(grazing) - sin_t) / (np.sin(grazing) + sin_t)


def luebbers_coefficient(n, phi_s, phi, sin_t, rn_angle="luebbers"):
    """Luebbers' heuristic (the far field of the UTD sum d1 + d2 + R_n d3 + R_0 d4) with the
    reference's impedance faces: R_0 at the grazing angle phi' on face 0; R_n at the diffracted
    ray's grazing angle on face n's plane (|sin(n pi - phi)|, Luebbers'), or with
    rn_angle="incident" at the incident wave's (ours and Sionna's), or "soft_unlit" that and
    R_n = -1 where face n is unlit (Sionna's)."""
    c = -np.exp(-1j * np.pi / 4) / (2 * n * np.sqrt(2 * np.pi * K))
    cot = lambda x: 1 / np.tan(x)
    d1 = cot((np.pi + (phi - phi_s)) / (2 * n))
    d2 = cot((np.pi - (phi - phi_s)) / (2 * n))
    d3 = cot((np.pi + (phi + phi_s)) / (2 * n))
    d4 = cot((np.pi - (phi + phi_s)) / (2 * n))
    r0 = impedance_reflection(phi_s, sin_t)
    incident = abs((n - 1) * np.pi - phi_s)
    incident = min(incident, np.pi - incident)
    if rn_angle == "luebbers":
        rn = impedance_reflection(np.arcsin(abs(np.sin(n * np.pi - phi))), sin_t)
    elif rn_angle == "soft_unlit" and phi_s >= (n - 1) * np.pi:
        rn = -1.0
    else:
        rn = impedance_reflection(incident, sin_t)
    return c * (d1 + d2 + rn * d3 + r0 * d4)


def development_set():
    """The heuristics' R_n angles against the exact solution on wedges, sources and materials
    the fixture does not hold (impedance faces on both sides): what a choice between them is
    made on. Prints |heuristic - exact| median / 90th percentile, dB."""
    laws = {"wet_ground": MATERIALS["wet_ground"], "concrete": MATERIALS["concrete"],
            "medium_dry_ground": (15.0, -0.1, 0.035, 1.63)}
    errs = {m: [] for m in ("incident", "luebbers", "soft_unlit")}
    for law in laws.values():
        eps = permittivity_of(law)
        for n in (1.6, 1.9):
            for phi_s in (0.2 * np.pi, 0.45 * np.pi, 0.7 * np.pi, 0.85 * np.pi):
                for a in receiver_angles(n, phi_s, MARGIN):
                    if a > (n - 0.02) * np.pi:
                        continue
                    for sin_t in (np.sqrt(eps), 1 / np.sqrt(eps)):
                        exact = exact_db(maliuzhinets_coefficient(n, phi_s, a, sin_t))
                        for mode, e in errs.items():
                            got = exact_db(luebbers_coefficient(n, phi_s, a, sin_t, mode))
                            e.append(abs(got - exact))
    for mode, e in errs.items():
        print(f"R_n {mode}: {len(e)} links, |heuristic - exact| median {np.median(e):.3f} dB, "
              f"90th percentile {np.percentile(e, 90):.3f} dB")


def check_reference():
    """The reference's own checks (see the module's doc); raises on any failure."""
    for big_phi in (0.75 * np.pi, np.pi):
        for z in (0.1, 1.2, 0.3 + 0.7j):
            lhs = psi(z + 2 * big_phi, big_phi) / psi(z - 2 * big_phi, big_phi)
            assert abs(lhs - 1 / np.tan(z / 2 + np.pi / 4)) < 1e-9, ("functional equation", z)
    for n in WEDGES:
        for phi_s, phi in ((0.3 * np.pi, 1.2 * np.pi), (0.8 * np.pi, 0.5 * np.pi)):
            for hard, sin_t in ((False, 1e7), (True, 0.0)):
                got = abs(maliuzhinets_coefficient(n, phi_s, phi, sin_t))
                want = abs(keller_coefficient(n, phi_s, phi, hard))
                assert abs(got / want - 1) < 1e-5, ("conductor limit", n, hard, got, want)
                # Luebbers' sum is exact for the conductor away from the shadow boundaries.
                lue = abs(luebbers_coefficient(n, phi_s, phi, sin_t))
                assert abs(lue / want - 1) < 1e-5, ("Luebbers' conductor limit", n, hard)
    big_phi = 0.75 * np.pi
    for sin_t in (0.4 + 0.3j, 4.3 - 0.46j, 0.23 + 0.02j):
        t = np.arcsin(complex(sin_t))
        for phi0 in (0.2, -0.5, 1.0):
            # The residue at the face-(+Phi) image pole is the wave that face reflects.
            r = -big_psi(2 * big_phi - phi0, big_phi, t, t) / big_psi(phi0, big_phi, t, t)
            want = impedance_reflection(big_phi - phi0, sin_t)
            assert abs(r - want) < 1e-9, ("face reflection", sin_t, phi0, r, want)
        d = lambda a, b: maliuzhinets_coefficient(1.5, a, b, sin_t)
        assert abs(d(0.4, 3.9) - d(3.9, 0.4)) < 1e-9 * abs(d(0.4, 3.9)), "reciprocity"
        flat = maliuzhinets_coefficient(1.0, 0.3 * np.pi, 0.6 * np.pi, sin_t)
        assert abs(flat) < 1e-12, ("a flat face diffracts", flat)
    print("reference checks passed: functional equation, conductor limits, face reflection, "
          "reciprocity, flat face")


def main(out_path):
    check_reference()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for material in MATERIALS:
            eps = permittivity(material)
            for n, sources in WEDGES.items():
                for phi_s_pi in sources:
                    phi_s = phi_s_pi * np.pi
                    tx = world(RHO_TX, phi_s)
                    angles = [a for a in receiver_angles(n, phi_s, MARGIN)
                              if a < (n - 0.02) * np.pi]
                    rxs = [world(RHO_RX, a) for a in angles]
                    for pol, sin_t in (("V", np.sqrt(eps)), ("H", 1 / np.sqrt(eps))):
                        sionna = sionna_gains(f"{tmp}/{material}-{n}-{phi_s_pi}-{pol}", n, tx,
                                              rxs, pol, material, THICKNESS)
                        for a, rx, s in zip(angles, rxs, sionna):
                            exact = exact_db(maliuzhinets_coefficient(n, phi_s, a, sin_t))
                            lue = exact_db(luebbers_coefficient(n, phi_s, a, sin_t))
                            rows.append([material, n, f"{phi_s_pi:.2f}", f"{a / np.pi:.6f}", pol,
                                         *(f"{c:.6f}" for c in tx), *(f"{c:.6f}" for c in rx),
                                         f"{exact:.4f}", f"{lue:.4f}", s])
                        print(f"{material}, n {n}, phi' {phi_s_pi} pi, {pol}: {len(rxs)} receivers")
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["material", "n", "phi_s_over_pi", "phi_over_pi", "polarization", "tx_x",
                    "tx_y", "tx_z", "rx_x", "rx_y", "rx_z", "exact_db", "luebbers_db",
                    "sionna_db"])
        w.writerows(rows)


if __name__ == "__main__":
    if sys.argv[1:] == ["--development-set"]:
        check_reference()
        development_set()
    else:
        main(sys.argv[1])
