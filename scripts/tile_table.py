#!/usr/bin/env python3
"""The per-job table of a tiled run submitted to Slurm (BENCHMARKS.md, "City scale").

Reads the run records the jobs printed (`--json`, one per log) in a submission folder,
`out/<graph>/slurm/<n>/`, and prints a Markdown table: per job (prefix, each tile, merge) its
wall time and peak RSS as kodama-dag measured them, and the slowest nodes.

    python3 scripts/tile_table.py out/bench_city_25km2/slurm/1
"""
import json
import re
import sys
from pathlib import Path


def record(log: Path):
    """The last JSON line of a job's log: its run record."""
    for line in reversed(log.read_text(errors="replace").splitlines()):
        line = line.strip()
        if line.startswith("{"):
            return json.loads(line)
    raise SystemExit(f"{log}: no run record (did the job fail? see the log)")


def main() -> None:
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    folder = Path(sys.argv[1])
    rows = []
    for log in sorted(folder.glob("*.out")):
        m = re.match(r"(prefix|gather-\d+|merge|tiles(?:-\d+)?)-(\d+)(?:_(\d+))?\.out$", log.name)
        if not m:
            continue
        rec = record(log)
        ran = [n for n in rec["nodes"] if n["status"] == "ran"]
        tile = ""
        if m.group(3) is not None:
            names = {n["id"].split("@")[1] for n in ran if "@" in n["id"]}
            tile = f"{int(m.group(3))} ({', '.join(sorted(names))})"
        slow = sorted(ran, key=lambda n: -n["ms"])[:2]
        order = {"prefix": 0, "merge": 2}.get(m.group(1), 1)
        rows.append((order, int(m.group(3) or 0), m.group(1), tile, rec, len(ran), slow))
    rows.sort(key=lambda r: (r[0], r[1]))
    print("| job | tile | wall (s) | peak RSS (MB) | nodes run | slowest nodes (s) |")
    print("|---|---|---|---|---|---|")
    walls, peaks = [], []
    for _, _, job, tile, rec, n_ran, slow in rows:
        slowest = ", ".join(f"{n['id'].split('@')[0]} {n['ms'] / 1000:.1f}" for n in slow)
        print(f"| {job} | {tile} | {rec['wall_s']:.1f} | {rec['peak_rss_mb']:.0f} | {n_ran} | {slowest} |")
        if tile:
            walls.append(rec["wall_s"])
            peaks.append(rec["peak_rss_mb"])
    if walls:
        print()
        print(
            f"{len(walls)} tiles: wall {min(walls):.1f}-{max(walls):.1f} s "
            f"(sum {sum(walls):.0f} s), peak RSS {min(peaks):.0f}-{max(peaks):.0f} MB"
        )


if __name__ == "__main__":
    main()
