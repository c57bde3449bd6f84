"""kodama-dag from Python: run graphs in process and read their artifacts as NumPy arrays.

    import kodama_dag
    run = kodama_dag.run("graphs/demo.ron")
    dsm = run.raster("dsm")            # xarray.DataArray when xarray is installed
    table = run.metrics("evaluate")    # dict of floats
    paths = kodama_dag.trace((run, "scene"), links, 3.5e9)   # Sionna RT-shaped a, tau, ...

The engine and the stages are the CLI's own (`kodama-dag run`), linked into this package: the same
graph files, the same cache (so a graph run from the CLI is read here without running again), the
same errors. See docs/python.md.
"""

from ._core import EngineError, UserError, __version__
from .api import (
    KindInfo,
    NodeFailed,
    NodeRecord,
    ParamInfo,
    PlanEntry,
    Run,
    SweepResult,
    explain,
    kinds,
    run,
    sweep,
)
from .radio import Paths, RadioMap, radio_map, trace
from .sionna_scene import sionna_foliage_loss_db, to_sionna, with_foliage

__all__ = [
    "EngineError",
    "KindInfo",
    "NodeFailed",
    "NodeRecord",
    "ParamInfo",
    "Paths",
    "PlanEntry",
    "RadioMap",
    "Run",
    "SweepResult",
    "UserError",
    "__version__",
    "explain",
    "kinds",
    "radio_map",
    "run",
    "sionna_foliage_loss_db",
    "sweep",
    "to_sionna",
    "trace",
    "with_foliage",
]
