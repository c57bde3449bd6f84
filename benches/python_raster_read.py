"""Reading a 4,000 x 4,000 raster artifact from Python: what it costs beyond the file read.

    maturin develop --release   # or pip install .
    python3 benches/python_raster_read.py [SIDE]   # default 4000

A graph makes one SynthTerrain raster of SIDE x SIDE float32 cells (64 MB at 4,000) into a fresh
cache; then `Run.raster(node, xarray=False)` reads it. The process's peak RSS is sampled around
the read (Linux: VmHWM, reset through /proc/self/clear_refs): the read maps the blob (the file,
MessagePack; its pages count in RSS once touched) and views the cells in it; a decode would
add the array's size again, a copy into NumPy once more. Prints the array size, the peak growth
over the read and their ratio, NumPy's flags (`owndata` False: not NumPy's memory; `writeable`
False: the file's pages) and the seconds.
"""

import gc
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import kodama_dag


def vm(field: str) -> int:
    """A /proc/self/status field in bytes."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"no {field} in /proc/self/status")


def reset_peak() -> None:
    # Writing 5 resets VmHWM to the current RSS (Linux 4.0 and later).
    Path("/proc/self/clear_refs").write_text("5")


def main() -> None:
    side = int(sys.argv[1]) if len(sys.argv) > 1 else 4000
    cell = 0.25
    with tempfile.TemporaryDirectory() as tmp:
        graph = Path(tmp) / "raster.ron"
        graph.write_text(
            "Graph(\n"
            f'    site: Site(crs: "EPSG:32618", origin: (583200.0, 4506600.0), cell_m: {cell}),\n'
            f"    nodes: {{ \"terrain\": SynthTerrain(size_m: ({side * cell}, {side * cell})) }},\n"
            "    outputs: {},\n"
            ")\n"
        )
        run = kodama_dag.run(graph, cache=Path(tmp) / "cache", out=False, quiet=True)
        blob = run.node("terrain").digest
        blob_bytes = sum(
            f.stat().st_size for f in (Path(tmp) / "cache").rglob(f"*{blob}*") if f.is_file()
        )
        gc.collect()
        before = vm("VmRSS")
        reset_peak()
        t = time.perf_counter()
        data, _ = run.raster("terrain", xarray=False)
        secs = time.perf_counter() - t
        peak = vm("VmHWM")
        assert data.shape == (side, side) and data.dtype == np.float32
        array = data.nbytes
        grew = peak - before
        print(f"raster {side} x {side} float32: {array / 1e6:.1f} MB; blob on disk {blob_bytes / 1e6:.1f} MB")
        print(f"peak RSS growth over the read: {grew / 1e6:.1f} MB = {grew / array:.2f} x the array")
        print(f"numpy owndata {data.flags.owndata}, writeable {data.flags.writeable}, "
              f"aligned {data.flags.aligned}")
        print(f"read in {secs:.3f} s")


if __name__ == "__main__":
    main()
