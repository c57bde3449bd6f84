"""The typed API over `kodama_dag._core`: runs, their records, and artifacts as NumPy."""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from . import _core




class NodeFailed(RuntimeError):
    """A run finished with failed nodes. `run` holds the record (outputs of the nodes that did
    succeed can still be read from it); `user_error` is True when the failure was the input's
    (the CLI's exit code 2)."""

    def __init__(self, message: str, run: "Run", user_error: bool):
        super().__init__(message)
        self.run = run
        self.user_error = user_error


@dataclass(frozen=True)
class NodeRecord:
    """What happened to one node in a run (`kodama-dag run --json`'s `nodes`)."""

    id: str
    kind: str
    status: str
    """"ran", "cached", "cutoff", "failed" or "skipped"."""
    reason: str
    seconds: float
    digest: str | None
    """blake3 of the node's output artifact (hex), if it has one."""
    error: str | None = None
    user_error: bool = False
    unit: str | None = None
    """What a raster output's values measure ("m", "dB", ...), written in its GeoTIFF's band."""


def _set_args(set: Mapping[str, object]) -> list[str]:
    """`{"node.key": value}` as the CLI's `--set node.key=VALUE` (values in RON syntax: numbers,
    booleans, strings quoted, lists and tuples as Python writes them)."""
    out = []
    for key, value in set.items():
        if not isinstance(key, str) or "." not in key:
            raise _core.UserError(f"set: expected keys like 'node.param', got {key!r}")
        out.append(f"{key}={_ron(value)}")
    return out


def _ron(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(float(v)):
            raise _core.UserError(f"set: expected a finite number, got {v!r}")
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list,)):
        return "[" + ", ".join(_ron(x) for x in v) + "]"
    if isinstance(v, tuple):
        return "(" + ", ".join(_ron(x) for x in v) + ")"
    raise _core.UserError(
        f"set: cannot write {type(v).__name__} {v!r} as a graph value; "
        "pass a number, bool, string, list or tuple, or the RON text itself as a string"
    )


def _progress_sink():
    """Where a run's progress lines go: `sys.stderr.write` (a notebook shows them under the
    cell, pytest captures them), or None when `sys.stderr` is the process's own terminal and
    the CLI's bars are drawn there."""
    err = sys.stderr
    if err is None:
        return None
    try:
        if err.isatty() and err.fileno() == 2:
            return None
    except (AttributeError, OSError, ValueError):
        pass
    return err.write


def _cache_dir(cache: "str | os.PathLike[str] | None") -> str:
    if cache is not None:
        return os.fspath(cache)
    return os.environ.get("KODAMA_DAG_CACHE", "cache")


def _data_dir(data: "str | os.PathLike[str] | None") -> str | None:
    return None if data is None else os.fspath(data)


class Run:
    """One run of a graph: its record and its artifacts, read from the cache on demand."""

    def __init__(self, record: dict, site: dict, cache: str):
        self.graph: str = record["graph"]
        self.records: list[NodeRecord] = [
            NodeRecord(
                id=n["id"],
                kind=n["kind"],
                status=n["status"].lower(),
                reason=n["reason"],
                seconds=n["ms"] / 1e3,
                digest=n.get("digest"),
                error=n.get("error"),
                user_error=n.get("user_error", False),
                unit=n.get("unit"),
            )
            for n in record["nodes"]
        ]
        self.outputs: dict[str, str] = dict(record.get("outputs", {}))
        """Declared outputs written: name -> path."""
        self.output_errors: dict[str, str] = {
            k: v["error"] for k, v in record.get("output_errors", {}).items()
        }
        self.wall_s: float = record.get("wall_s", float("nan"))
        self.peak_rss_mb: float | None = record.get("peak_rss_mb")
        self.crs: str = site["crs"]
        """The site's projected CRS (`EPSG:<code>`)."""
        self.origin: tuple[float, float] = tuple(site["origin"])  # type: ignore[assignment]
        """The site frame's origin in the CRS (easting, northing), metres."""
        self.cell_m: float = float(site["cell_m"])
        """The site's default raster cell, metres."""
        self.cache: str = cache

    def __repr__(self) -> str:
        counts: dict[str, int] = {}
        for r in self.records:
            counts[r.status] = counts.get(r.status, 0) + 1
        what = ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
        return f"<Run {self.graph}: {what}; {self.wall_s:.1f} s>"

    def node(self, node: str) -> NodeRecord:
        """The record of `node`; KeyError naming the nodes there are when it is not in the run."""
        for r in self.records:
            if r.id == node:
                return r
        raise KeyError(
            f"node {node!r} is not in this run; its nodes: {', '.join(r.id for r in self.records)}"
        )

    def artifact(self, node: str) -> dict[str, Any]:
        """The raw artifact of `node` as `_core` reads it: a dict with `type` and NumPy arrays."""
        r = self.node(node)
        if r.digest is None:
            raise KeyError(f"node {node!r} has no output in this run ({r.status}: {r.reason})")
        return _core.artifact(self.cache, r.digest)

    def _typed(self, node: str, want: str) -> dict[str, Any]:
        a = self.artifact(node)
        if a["type"] != want:
            raise TypeError(f"node {node!r} makes a {a['type']}, not a {want}")
        return a

    def raster(self, node: str, *, xarray: bool | None = None):
        """A raster artifact: an `xarray.DataArray` (y, x) of float32 with cell-centre
        coordinates in the site's CRS (metres; no-data is NaN), or, when xarray is not installed
        or `xarray=False`, a `(data, transform)` pair where `transform` is the GDAL geotransform
        of the CRS coordinates. The array is the decoded artifact's own buffer (no copy)."""
        a = self._typed(node, "Raster")
        data: np.ndarray = a["data"]
        x0 = self.origin[0] + a["x0"]
        y0 = self.origin[1] + a["y0"]
        cell = a["cell_m"]
        transform = (x0, cell, 0.0, y0, 0.0, -cell)
        if xarray is False:
            return data, transform
        try:
            import xarray as xr
        except ImportError:
            if xarray:
                raise
            return data, transform
        h, w = data.shape
        xs = x0 + cell * (np.arange(w) + 0.5)
        ys = y0 - cell * (np.arange(h) + 0.5)
        epsg = self.crs.split(":", 1)[1] if self.crs.startswith("EPSG:") else None
        da = xr.DataArray(
            data,
            dims=("y", "x"),
            coords={"y": ys, "x": xs},
            name=node,
            attrs={
                "crs": self.crs,
                "site_origin": self.origin,
                "cell_m": cell,
                "transform": transform,
                "_FillValue": np.float32(np.nan),
            },
        )
        if epsg is not None:
            # The CF grid-mapping coordinate rioxarray reads (`da.rio.crs`), without needing it.
            da = da.assign_coords(spatial_ref=xr.DataArray(0, attrs={"crs_wkt": self.crs, "spatial_ref": self.crs, "epsg": int(epsg)}))
            da.attrs["grid_mapping"] = "spatial_ref"
        return da

    def points(self, node: str) -> dict[str, np.ndarray]:
        """A point set: `xyz` (N, 3) float32 in the site frame (add `origin` for the CRS),
        `classification` (ASPRS codes), `intensity`, `return_number`, `number_of_returns`,
        `rgb` when present."""
        a = self._typed(node, "Points")
        a.pop("type")
        return a

    def scene(self, node: str) -> list[dict[str, Any]]:
        """A scene's objects, each a dict: `id`, `class` ("Terrain", "Building", ...),
        `vertices` (V, 3) float32 in the site frame, `triangles` (T, 3) uint32, `materials` (T,)
        uint8, `material_names` (code -> ITU-R P.2040 name, as Sionna RT's `itu_type`),
        `material_thickness_m` (code -> the slab thickness transmission uses)."""
        a = self._typed(node, "Scene")
        names, thickness = a["material_names"], a["material_thickness_m"]
        for o in a["objects"]:
            o["material_names"] = names
            o["material_thickness_m"] = thickness
        return a["objects"]

    def footprints(self, node: str):
        """Building footprints in the site's CRS: a `geopandas.GeoDataFrame` when geopandas is
        installed, else a GeoJSON FeatureCollection dict (polygons in CRS coordinates)."""
        a = self._typed(node, "Footprints")
        ox, oy = self.origin
        features = []
        for item in a["items"]:
            polys = [[(ring + (ox, oy)).tolist() for ring in poly] for poly in item["polygons"]]
            geometry = (
                {"type": "Polygon", "coordinates": polys[0]}
                if len(polys) == 1
                else {"type": "MultiPolygon", "coordinates": polys}
            )
            props = {k: item[k] for k in ("id", "height_m", "min_height_m", "levels", "min_level")}
            features.append({"type": "Feature", "geometry": geometry, "properties": props})
        fc = {"type": "FeatureCollection", "features": features}
        try:
            import geopandas as gpd
        except ImportError:
            return fc
        return gpd.GeoDataFrame.from_features(features, crs=self.crs)

    def links(self, node: str):
        """Measured or predicted links as columns (`tx_id`, `tx_x`, `tx_y`, `rx_...`, `freq_hz`,
        `path_loss_db`, `rx_power_dbm`, `tx_eirp_dbm`, `los`; x/y in the site frame, and each
        end's WGS 84 `tx_lon`, `tx_lat`, `rx_lon`, `rx_lat` in degrees): a `pandas.DataFrame`
        when pandas is installed, else a dict of columns."""
        a = self._typed(node, "Measurements")
        a.pop("type")
        heights = a.pop("heights")
        a["tx_height"] = [h[0] for h in heights]
        a["rx_height"] = [h[1] for h in heights]
        for end in ("tx", "rx"):
            a[f"{end}_lon"], a[f"{end}_lat"] = self.lon_lat(a[f"{end}_x"], a[f"{end}_y"])
        try:
            import pandas as pd
        except ImportError:
            return a
        return pd.DataFrame(a)

    def lon_lat(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """WGS 84 longitudes and latitudes (degrees) of site-frame points `x`, `y` (metres),
        as the exported CSVs give them; NaN where a coordinate is not finite."""
        xs = np.asarray(x, dtype=np.float64).ravel()
        ys = np.asarray(y, dtype=np.float64).ravel()
        return _core.lon_lat(self.crs, (float(self.origin[0]), float(self.origin[1])),
                             xs.tolist(), ys.tolist())

    def export(
        self, node: str, dest: "str | os.PathLike[str]", *, overwrite: bool = False
    ) -> Path:
        """Writes `node`'s artifact to `dest` in the format its name's extension gives, as a
        graph output of that name would be written (`dsm.tif`, `twin.glb`, `twin.sionna` (a
        Sionna RT folder with `site.json`), `twin.3dtiles`, `links.csv`, ...), never half-written.
        An existing `dest` is refused (with `overwrite`, an existing file is replaced; a folder
        never is). Returns `dest`."""
        r = self.node(node)
        if r.digest is None:
            raise KeyError(f"node {node!r} has no output in this run ({r.status}: {r.reason})")
        site = (self.crs, (float(self.origin[0]), float(self.origin[1])), self.cell_m)
        band = (r.unit, f"{r.id} ({r.kind})")
        _core.export(self.cache, r.digest, site, os.fspath(dest), overwrite, band)
        return Path(dest)

    def metrics(self, node: str) -> dict[str, float]:
        """A metrics artifact: name -> value."""
        return dict(self._typed(node, "Metrics")["values"])


def run(
    graph: "str | os.PathLike[str]",
    *,
    set: Mapping[str, object] | None = None,
    targets: Sequence[str] = (),
    cache: "str | os.PathLike[str] | None" = None,
    out: "str | os.PathLike[str] | None | bool" = None,
    jobs: int | None = None,
    data: "str | os.PathLike[str] | None" = None,
    allow_outside: bool = False,
    tile_m: float | None = None,
    halo_m: float | None = None,
    quiet: bool = False,
    check: bool = True,
) -> Run:
    """Runs the graph file `graph` as `kodama-dag run` does, in this process, and returns the run.

    - `set`: parameter overrides, `{"node.param": value}` (the CLI's `--set`).
    - `targets`: only these nodes and what they need (all when empty).
    - `cache`: the cache folder (default `$KODAMA_DAG_CACHE`, else `./cache`); shared with the CLI.
    - `out`: where declared outputs go (default `out/<graph stem>`, as the CLI); False: none.
    - `jobs`: worker threads (default all cores).
    - `data`, `allow_outside`, `tile_m`, `halo_m`: the CLI's `--data`, `--allow-outside`,
      `--tile-m`, `--halo-m`.
    - `quiet`: warnings and errors only (else one line per node and, for long stages, per tenth
      of their work; bars when `sys.stderr` is the process's terminal). Lines go through
      `sys.stderr`, so a notebook shows them under the cell.
    - `check`: raise `NodeFailed` when a node failed (else return the run with its failures).

    Raises `UserError` for what the CLI answers with exit code 2 (a bad graph, parameter or
    input file: the message names the file and the place), `EngineError` for a failing cache or
    output folder. The GIL is released while the graph runs.
    """
    graph = os.fspath(graph)
    if isinstance(out, bool):
        if out:
            raise _core.UserError("out: expected a folder, None (out/<graph stem>) or False (none)")
        out_dir = None
    elif out is None:
        stem = Path(graph).stem
        # As the CLI names it: a stem that names no file of its own (`...ron`: `..`) is "graph".
        out_dir = os.path.join("out", stem if stem not in ("", ".", "..") else "graph")
    else:
        out_dir = os.fspath(out)
    cache_dir = _cache_dir(cache)
    record, site = _core.run(
        graph,
        _set_args(set or {}),
        cache_dir,
        out_dir,
        list(targets),
        jobs,
        _data_dir(data),
        allow_outside,
        tile_m,
        halo_m,
        quiet,
        _progress_sink(),
    )
    result = Run(json.loads(record), site, cache_dir)
    failed = [r for r in result.records if r.status == "failed"]
    if check and (failed or result.output_errors):
        lines = [f'node "{r.id}" ({r.kind}) failed: {r.error}' for r in failed]
        lines += [f'output "{k}" was not written: {v}' for k, v in result.output_errors.items()]
        user = any(r.user_error for r in failed)
        raise NodeFailed("\n".join(lines), result, user)
    return result


class SweepResult:
    """A finished sweep: the table of its variants' metrics and each variant's run."""

    def __init__(self, d: dict, cache: str):
        self.name: str = d["name"]
        #: The axes, in the sweep file's order.
        self.axes: list[str] = list(d["axes"])
        #: The metrics asked for, `NODE.KEY`.
        self.metric_names: list[str] = list(d["metrics"])
        #: Where the table (table.md, table.csv) and the variants' outputs went.
        self.out = Path(d["out"])
        variants = d["variants"]
        #: Each variant's name (`axis=label,...`, as in the table), in run order.
        self.variants: list[str] = [
            ",".join(f"{a}={l}" for a, l in v["labels"]) for v in variants
        ]
        self._labels = [dict(v["labels"]) for v in variants]
        self._metrics = [list(v["metrics"]) for v in variants]
        self._runs = [Run(json.loads(v["record"]), d["site"], cache) for v in variants]

    def __repr__(self) -> str:
        return f"SweepResult({self.name!r}: {len(self.variants)} variants, {len(self.metric_names)} metrics)"

    def run(self, variant: "str | int") -> Run:
        """One variant's run (by name or position), to read its artifacts."""
        if isinstance(variant, int):
            return self._runs[variant]
        try:
            return self._runs[self.variants.index(variant)]
        except ValueError:
            raise KeyError(
                f"no variant {variant!r}; the sweep has {', '.join(self.variants)}"
            ) from None

    def table(self, *, pandas: bool | None = None):
        """The sweep's table: a row per variant (index: its name), a column per axis (the
        variant's label on it) and per metric (NaN where the variant's graph does not make it).
        A pandas DataFrame when pandas is installed (or `pandas=True`), else a dict of columns."""
        cols: dict[str, list] = {"variant": list(self.variants)}
        for a in self.axes:
            cols[a] = [lab[a] for lab in self._labels]
        for k, m in enumerate(self.metric_names):
            cols[m] = [row[k] for row in self._metrics]
        if pandas is False:
            return cols
        try:
            import pandas as pd
        except ImportError:
            if pandas:
                raise
            return cols
        return pd.DataFrame(cols).set_index("variant")


def sweep(
    file: "str | os.PathLike[str]",
    *,
    set: Mapping[str, object] | None = None,
    cache: "str | os.PathLike[str] | None" = None,
    out: "str | os.PathLike[str] | None" = None,
    jobs: int | None = None,
    data: "str | os.PathLike[str] | None" = None,
    allow_outside: bool = False,
    quiet: bool = False,
) -> SweepResult:
    """Runs the sweep file `file` as `kodama-dag sweep` does, in this process: every variant
    through one cache (a node shared by variants runs once), the table written to `out`
    (default `out/<sweep stem>`). `set` applies to every variant, before its own overrides.

    Raises `UserError` for a bad sweep or base graph (exit code 2 in the CLI), `EngineError`
    when a variant's node failed or the cache did (exit code 1); finished variants stay cached,
    so running it again resumes. The GIL is released while it runs."""
    cache_dir = _cache_dir(cache)
    d = _core.sweep(
        os.fspath(file),
        _set_args(set or {}),
        cache_dir,
        None if out is None else os.fspath(out),
        jobs,
        _data_dir(data),
        allow_outside,
        quiet,
        _progress_sink(),
    )
    return SweepResult(d, cache_dir)


@dataclass(frozen=True)
class PlanEntry:
    """What `run` would do for one node, and why (`kodama-dag explain`)."""

    id: str
    kind: str
    plan: str
    """"cached", "run" or "maybe" (runs unless what runs upstream reproduces its output)."""
    reason: str


def explain(
    graph: "str | os.PathLike[str]",
    *,
    set: Mapping[str, object] | None = None,
    targets: Sequence[str] = (),
    cache: "str | os.PathLike[str] | None" = None,
    data: "str | os.PathLike[str] | None" = None,
    allow_outside: bool = False,
) -> list[PlanEntry]:
    """What `run` would do for each node and why, without running anything."""
    plan = _core.explain(
        os.fspath(graph),
        _set_args(set or {}),
        _cache_dir(cache),
        list(targets),
        _data_dir(data),
        allow_outside,
    )
    return [PlanEntry(**e) for e in json.loads(plan)]


@dataclass(frozen=True)
class KindInfo:
    """A node kind a graph may name (`kodama-dag kinds`)."""

    name: str
    version: int
    doc: str
    output: str
    inputs: tuple[tuple[str, str, str, str], ...]
    """(name, artifact type, "one" | "optional" | "many", description) per input."""
    reports: tuple[tuple[str, str, str], ...]
    """(name, artifact type, description) per report the kind makes beside its output."""
    params: tuple[ParamInfo, ...]
    """Every param, in the order of the stage's source."""
    reference: str
    """The kind's reference as `kodama-dag kinds KIND` prints it: inputs, output, reports, and
    every param (nested ones too) with its type, default and documentation."""


@dataclass(frozen=True)
class ParamInfo:
    """One param of a node kind, read from the stage's own source."""

    name: str
    type: str
    """The Rust type as written (`f64`, `(f64, f64, f64)`, `Option<f64>`, `MapOptions`)."""
    required: bool
    """Whether a graph must give it."""
    default: Any
    """Its default (numbers, strings, lists, dicts; an enum variant by name), None when required
    or when a default cannot be read."""
    doc: str
    """Its documentation: meaning, unit, convention."""


def kinds() -> dict[str, KindInfo]:
    """Every node kind, by name."""
    out = {}
    for k in _core.kinds():
        out[k["name"]] = KindInfo(
            name=k["name"],
            version=k["version"],
            doc=k["doc"],
            output=k["output"],
            inputs=tuple(tuple(i) for i in k["inputs"]),
            reports=tuple(tuple(r) for r in k["reports"]),
            params=tuple(
                ParamInfo(
                    name=name,
                    type=ty,
                    required=required,
                    default=None if default is None else json.loads(default),
                    doc=doc,
                )
                for name, ty, required, default, doc in k["params"]
            ),
            reference=k["reference"],
        )
    return out
