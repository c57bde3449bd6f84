"""The tracer from Python: `trace` (links) and `radio_map` (one transmitter over a plane), on a
Sionna RT scene file or a run's scene, with results shaped as Sionna RT's.

The same code as `kodama-dag trace`/`radiomap` and the graph's `Trace`/`RadioMap` nodes
(README, "Radio: tracing and radio maps"); defaults are Sionna RT's (depth 3, LOS, specular
reflection and transmission on, diffraction and diffuse off, 10^6 rays).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping, Sequence, Tuple, Union

import numpy as np

from . import _core

if TYPE_CHECKING:
    from .api import Run

#: A scene: a Sionna RT XML file, or `(run, node)` for a scene node of a finished run.
SceneLike = Union[str, "os.PathLike[str]", Tuple["Run", str]]

_LINK_COLUMNS = ("tx_x", "tx_y", "tx_z", "rx_x", "rx_y", "rx_z")


def _scene_source(scene: SceneLike):
    if isinstance(scene, tuple):
        if len(scene) != 2:
            raise _core.UserError("scene: expected a file, or (run, node) for a run's scene node")
        run, node = scene
        r = run.node(node)
        if r.digest is None:
            raise _core.UserError(f"scene: node {node!r} has no output in this run ({r.status})")
        return (run.cache, r.digest)
    return os.fspath(scene)


def _links_array(links: Any) -> np.ndarray:
    if hasattr(links, "columns") or isinstance(links, Mapping):
        missing = [c for c in _LINK_COLUMNS if c not in links]
        if missing:
            raise _core.UserError(
                f"links: expected columns {', '.join(_LINK_COLUMNS)}; missing {', '.join(missing)}"
            )
        links = np.column_stack([np.asarray(links[c], dtype=np.float64) for c in _LINK_COLUMNS])
    arr = np.ascontiguousarray(links, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 6:
        arr = arr.reshape(1, 6)
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise _core.UserError(
            f"links: expected shape (N, 6) (tx x, y, z, rx x, y, z), got {arr.shape}"
        )
    return arr


def _physics(
    max_depth: int,
    los: bool,
    reflection: bool,
    transmission: bool,
    diffraction: bool,
    diffuse: bool,
    scattering_coefficient: float,
    rays: int,
    tx_antenna: str,
    extrapolate: bool,
) -> dict[str, Any]:
    for name, v in (("max_depth", max_depth), ("rays", rays)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v < 2**32:
            raise _core.UserError(f"{name}: expected a whole number from 0 to 2^32 - 1, got {v!r}")
    return {
        "max_depth": int(max_depth),
        "los": bool(los),
        "reflection": bool(reflection),
        "transmission": bool(transmission),
        "diffraction": bool(diffraction),
        "diffuse": bool(diffuse),
        "scattering_coefficient": float(scattering_coefficient),
        "rays": int(rays),
        "tx_antenna": str(tx_antenna),
        "extrapolate": bool(extrapolate),
    }


@dataclass(frozen=True)
class Paths:
    """The paths of N links, padded to the most paths P of any link and the depth D.

    As Sionna RT's `Paths` with one transmitter and one receiver per link (the link axis in
    place of Sionna's receiver and transmitter axes, single antennas): `a` complex (N, P), the
    path's complex gain without the phase of its delay; `tau` (N, P) seconds, -1 where there is
    no path; `valid` (N, P); `interactions` (N, P, D) in Sionna RT's `InteractionType` codes
    (0 none, 1 specular reflection, 4 refraction, i.e. transmission through a slab, 8
    diffraction); `vertices` (N, P, D, 3) the interaction points; `triangles` (N, P, D) the
    scene triangle met, -1 past the last interaction. Per link: `gain_db` (Σ|a|² in dB, what
    `kodama-dag trace` writes as path_gain_db; -inf without a path), `coherent_gain_db` (|Σ a
    e^{-j2πfτ}|²), `diffuse_gain_db` (the diffusely scattered power, summed, not listed).
    """

    gain_db: np.ndarray
    coherent_gain_db: np.ndarray
    diffuse_gain_db: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    valid: np.ndarray
    interactions: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray

    def cir(self) -> tuple[np.ndarray, np.ndarray]:
        """(a, tau), as Sionna RT's `Paths.cir(out_type="numpy")` gives them for single antennas
        and one time step: a (N, P) complex with 0 where no path, tau (N, P) with -1 there."""
        return self.a, self.tau

    def __len__(self) -> int:
        return int(self.gain_db.shape[0])

    def __repr__(self) -> str:
        return f"Paths({len(self)} links, at most {self.a.shape[1]} paths each)"


def trace(
    scene: SceneLike,
    links: Any,
    freq_hz: float,
    *,
    max_depth: int = 3,
    los: bool = True,
    reflection: bool = True,
    transmission: bool = True,
    diffraction: bool = False,
    diffuse: bool = False,
    scattering_coefficient: float = 0.0,
    rays: int = 1_000_000,
    tx_antenna: str = "iso",
    extrapolate: bool = False,
) -> Paths:
    """Traces the links `links` through `scene` at `freq_hz` and returns their `Paths`.

    - `scene`: a Sionna RT scene file (Mitsuba XML + PLY; its materials' slab thicknesses as
      Sionna RT reads them), or `(run, "node")` for a run's scene node (the site frame).
    - `links`: an array (N, 6) of tx x, y, z, rx x, y, z in the scene's frame (metres), or a
      table (DataFrame or dict) with those columns named `tx_x` ... `rx_z`.
    - `tx_antenna`: `"iso"`, `"dipole"` or `"tr38901:BEARING_DEG:TILT_DEG"`; receivers are
      isotropic.

    Raises `UserError` for a scene, link or setting the CLI would refuse (exit 2). The GIL is
    released while the paths are traced."""
    result = _core.trace(
        _scene_source(scene),
        _links_array(links),
        float(freq_hz),
        _physics(
            max_depth, los, reflection, transmission, diffraction, diffuse,
            scattering_coefficient, rays, tx_antenna, extrapolate,
        ),
    )
    return Paths(**result)


@dataclass(frozen=True)
class RadioMap:
    """One transmitter's path gain over a horizontal plane, as Sionna RT's `RadioMap`:
    `path_gain` (1, H, W) linear, 0 where no ray arrived; `cell_centers` (H, W, 3); rows run
    south to north (y grows with the row, as Sionna RT's cells do), columns west to east.
    `path_gain_db` is 10 log10 of it (NaN where no ray arrived); `transform` is the GDAL
    geotransform of the same cells written north up (as `kodama-dag radiomap` writes the
    GeoTIFF), for rasterio or xarray."""

    path_gain: np.ndarray
    path_gain_db: np.ndarray
    cell_centers: np.ndarray
    cell_m: float
    transform: tuple[float, float, float, float, float, float]

    def __repr__(self) -> str:
        _, h, w = self.path_gain.shape
        return f"RadioMap({w} x {h} cells of {self.cell_m} m)"


def radio_map(
    scene: SceneLike,
    tx: Sequence[float],
    freq_hz: float,
    *,
    cell_m: float = 10.0,
    height_m: float = 1.5,
    max_depth: int = 3,
    los: bool = True,
    reflection: bool = True,
    transmission: bool = True,
    diffraction: bool = False,
    diffuse: bool = False,
    scattering_coefficient: float = 0.0,
    rays: int = 1_000_000,
    tx_antenna: str = "iso",
    extrapolate: bool = False,
) -> RadioMap:
    """The path gain from a transmitter at `tx` (x, y, z in the scene's frame) over Sionna RT's
    default plane: the scene's horizontal extent in cells of `cell_m`, centred on it, at
    `height_m`. Other arguments as `trace`'s. The GIL is released while the rays are shot."""
    tx = tuple(float(v) for v in tx)
    if len(tx) != 3:
        raise _core.UserError(f"tx: expected (x, y, z), got {len(tx)} numbers")
    d = _core.radio_map_at(
        _scene_source(scene),
        tx,
        float(freq_hz),
        float(cell_m),
        float(height_m),
        _physics(
            max_depth, los, reflection, transmission, diffraction, diffuse,
            scattering_coefficient, rays, tx_antenna, extrapolate,
        ),
    )
    north_up = d["data"]
    h, w = north_up.shape
    cell = d["cell_m"]
    # Sionna RT's rows run south to north: the raster's rows, north first, flipped.
    gain = np.nan_to_num(north_up[::-1], nan=0.0)[None, :, :]
    gain_db = d["data_db"][::-1]
    xs = d["x0"] + (np.arange(w) + 0.5) * cell
    ys = d["y0"] - h * cell + (np.arange(h) + 0.5) * cell
    gx, gy = np.meshgrid(xs, ys)
    centers = np.stack([gx, gy, np.full_like(gx, float(height_m))], axis=-1)
    return RadioMap(
        path_gain=gain,
        path_gain_db=gain_db,
        cell_centers=centers,
        cell_m=cell,
        transform=(d["x0"], cell, 0.0, d["y0"], 0.0, -cell),
    )
