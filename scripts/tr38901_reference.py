"""3GPP TR 38.901 path loss for the reference scripts (numpy): Table 7.4.1-1's UMa and
UMi-Street Canyon formulas, LOS and NLOS mixed power-weighted by Table 7.4.2-1's LOS probability,
and free space. Heights in metres, fc in GHz, distances in metres. Shared by duke_reference.py
(the fixture tests/duke.rs checks) and duke_split.py (docs/research/duke.md's figures).
"""
from collections import namedtuple

import numpy as np

C = 3.0e8

# LOS: a + b log10(d3D) + 20 log10(fc) before the breakpoint, a + 40 log10(d3D) + 20 log10(fc)
# - k log10(d'BP² + (hBS - hUT)²) after it; NLOS: max(LOS, na + nb log10(d3D) + nc log10(fc)
# - nh (hUT - 1.5)); LOS probability 18/d + exp(-d/d2)(1 - 18/d) beyond 18 m.
Scenario = namedtuple("Scenario", "a b k na nb nc nh d2")
UMA = Scenario(28.0, 22.0, 9.0, 13.54, 39.08, 20.0, 0.6, 63.0)
UMI = Scenario(32.4, 21.0, 9.5, 22.4, 35.3, 21.3, 0.3, 36.0)


def pathloss(d2d, fc, s, h_bs, h_ut):
    """Scenario `s`'s path loss (dB) at 2-D distances `d2d`, mixed over LOS and NLOS."""
    d3d = np.sqrt(d2d**2 + (h_bs - h_ut) ** 2)
    dbp = 4 * (h_bs - 1) * (h_ut - 1) * fc * 1e9 / C
    los = np.where(d2d <= dbp, s.a + s.b * np.log10(d3d) + 20 * np.log10(fc),
                   s.a + 40 * np.log10(d3d) + 20 * np.log10(fc)
                   - s.k * np.log10(dbp**2 + (h_bs - h_ut) ** 2))
    nlos = np.maximum(los, s.na + s.nb * np.log10(d3d) + s.nc * np.log10(fc) - s.nh * (h_ut - 1.5))
    pr = np.where(d2d <= 18, 1.0, (18 / d2d + np.exp(-d2d / s.d2) * (1 - 18 / d2d)))
    return -10 * np.log10(pr * 10 ** (-los / 10) + (1 - pr) * 10 ** (-nlos / 10))


def fspl(d3d, fc):
    """Free-space path loss (dB) at 3-D distances `d3d`."""
    return 20 * np.log10(d3d) + 20 * np.log10(fc * 1e9) - 147.55


def sector_gain_db(bearing_deg, boresight_deg, down_deg):
    """The TR 38.901 sector element's gain (dBi, Table 7.3-1: 65° beamwidths, 30 dB front-to-back,
    8 dBi peak) toward grid bearing `bearing_deg` and `down_deg` below the horizon, for a boresight
    at grid bearing `boresight_deg` with no tilt (nodes/src/rf/antenna.rs `gain`)."""
    phi = (np.asarray(bearing_deg) - boresight_deg + 180.0) % 360.0 - 180.0
    theta = 90.0 + np.asarray(down_deg)
    a_v = -np.minimum(12 * ((theta - 90) / 65) ** 2, 30)
    a_h = -np.minimum(12 * (phi / 65) ** 2, 30)
    return -np.minimum(-(a_v + a_h), 30) + 8.0
