#!/usr/bin/env python3
"""The family table of a city-family sweep (graphs/sweeps/family_test.ron, family_dev.ron).

Reads the sweep's table.csv and prints, as Markdown, one row per city-transmitter pair (the full
twin, the Sec. 4.1 solids, the OSM baseline and 3GPP, P2P RMSE in dB; the twin's NLOS RMSE), then
each column's mean, sample standard deviation and range over the pairs, the share of pairs where
the full twin beats the solids, and the mean gain of the twin over each other model with its
spread. A gain smaller than its spread is reported as "not shown", as the project's evaluation
rule asks.

    python3 scripts/family_table.py out/family_test/table.csv

A leave-one-out ablation's table (graphs/sweeps/family_ablation.ron: a "stage" column beside the
site) gives instead each stage's gain: the P2P RMSE of the twin without that stage minus the full
twin's, per pair, with its mean, spread and verdict, overall and over NLOS links.
"""

import csv
import math
import sys

COLUMNS = [
    ("full twin", "twin_eval.p2p_rmse_db"),
    ("twin NLOS", "twin_eval.nlos/p2p_rmse_db"),
    ("Sec. 4.1 solids", "solids_eval.p2p_rmse_db"),
    ("OSM baseline", "osm_eval.p2p_rmse_db"),
    ("3GPP UMi", "tr38901_eval.p2p_rmse_db"),
    ("links", "twin_eval.links"),
]


def mean_sd(xs):
    m = sum(xs) / len(xs)
    sd = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1)) if len(xs) > 1 else float("nan")
    return m, sd


def ablation(path, rows):
    """Each stage's gain per pair: the twin without it minus the full twin, P2P and NLOS."""
    keys = ["twin_eval.p2p_rmse_db", "twin_eval.nlos/p2p_rmse_db"]
    missing = [k for k in ["site", *keys] if k not in rows[0]]
    if missing:
        sys.exit(f"{path}: no column {', '.join(missing)} (is this family_ablation's table?)")
    by = {(r["site"], r["stage"]): r for r in rows}
    sites = sorted({r["site"] for r in rows})
    stages = [s for s in dict.fromkeys(r["stage"] for r in rows) if s != "full"]
    if not all((s, "full") in by for s in sites):
        sys.exit(f"{path}: every site needs a \"full\" row to measure gains against")
    print("| stage left out | gain, P2P (dB) | spread | verdict | gain, NLOS (dB) | spread | verdict | pairs where it helps |")
    print("|---|---|---|---|---|---|---|---|")
    for stage in stages:
        cells = []
        gains = {}
        for key in keys:
            g = [float(by[(s, stage)][key]) - float(by[(s, "full")][key])
                 for s in sites if (s, stage) in by]
            m, sd = mean_sd(g)
            gains[key] = g
            cells += [f"{m:+.2f}", f"{sd:.2f}", "shown" if abs(m) > sd else "not shown"]
        helps = sum(x > 0 for x in gains[keys[0]])
        print(f"| {stage} | " + " | ".join(cells) + f" | {helps} of {len(gains[keys[0]])} |")
    print()
    print("A positive gain: the twin is that much better (lower RMSE) with the stage than without it.")


def main(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{path}: no variants in the table")
    if "stage" in rows[0]:
        ablation(path, rows)
        return
    missing = [key for _, key in COLUMNS if key not in rows[0]]
    if missing:
        sys.exit(f"{path}: no column {', '.join(missing)} (is this a family sweep's table?)")
    label = "site" if "site" in rows[0] else next(iter(rows[0]))
    vals = {key: [float(r[key]) for r in rows] for _, key in COLUMNS}
    print("| pair | " + " | ".join(name for name, _ in COLUMNS) + " |")
    print("|---|" + "---|" * len(COLUMNS))
    for i, r in enumerate(rows):
        cells = [f"{vals[key][i]:.0f}" if key.endswith("links") else f"{vals[key][i]:.2f}"
                 for _, key in COLUMNS]
        print(f"| {r[label]} | " + " | ".join(cells) + " |")
    stats = [mean_sd(vals[key]) for _, key in COLUMNS]
    print("| mean | " + " | ".join(f"{m:.2f}" for m, _ in stats) + " |")
    print("| standard deviation | " + " | ".join(f"{s:.2f}" for _, s in stats) + " |")
    print("| range | " + " | ".join(
        f"{min(vals[key]):.2f}-{max(vals[key]):.2f}" for _, key in COLUMNS) + " |")
    twin = vals["twin_eval.p2p_rmse_db"]
    solids = vals["solids_eval.p2p_rmse_db"]
    beats = sum(t < s for t, s in zip(twin, solids))
    print()
    print(f"Full twin better than the Sec. 4.1 solids on {beats} of {len(rows)} pairs "
          f"({100.0 * beats / len(rows):.0f} %).")
    for name, key in COLUMNS[2:5]:
        gains = [o - t for o, t in zip(vals[key], twin)]
        m, sd = mean_sd(gains)
        verdict = "shown" if abs(m) > sd else "not shown"
        print(f"- gain of the full twin over {name}: {m:+.2f} dB, spread {sd:.2f} dB ({verdict})")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
