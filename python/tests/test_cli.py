"""The command line inside the wheel (`python -m kodama_dag`, the `kodama-dag` script) against the
CLI contract: the same run record, the same exit codes, results on stdout, errors on stderr."""

import json
import subprocess
import sys
from pathlib import Path

import kodama_dag

SMALL = Path(__file__).parent / "small.ron"


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "kodama_dag", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_run_prints_the_record_and_a_second_run_hits_the_cache(tmp_path):
    args = ["run", str(SMALL), "--cache", str(tmp_path / "c"), "--out", str(tmp_path / "o")]
    first = cli(*args, "--json", "--quiet", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    record = json.loads(first.stdout)
    assert [n["id"] for n in record["nodes"]] == [
        "city", "truth", "footprints", "lidar", "dsm", "dsm_stats"
    ]
    assert all(n["status"] == "ran" for n in record["nodes"])
    assert (tmp_path / "o" / "dsm.tif").is_file()
    second = json.loads(cli(*args, "--json", "--quiet", cwd=tmp_path).stdout)
    assert all(n["status"] == "cached" for n in second["nodes"])
    # The API reads what the command line made, without running anything.
    again = kodama_dag.run(SMALL, cache=tmp_path / "c", out=tmp_path / "o2", quiet=True)
    assert [r.digest for r in again.records] == [n["digest"] for n in record["nodes"]]


def test_a_bad_graph_is_exit_2_naming_the_file(tmp_path):
    bad = tmp_path / "bad.ron"
    bad.write_text('Graph(site: Site(crs: "EPSG:32618", origin: (0.0, 0.0), cell_m: -1.0), nodes: {}, outputs: {})')
    r = cli("run", str(bad), "--cache", str(tmp_path / "c"), cwd=tmp_path)
    assert r.returncode == 2
    assert "bad.ron" in r.stderr
    assert r.stdout == ""


def test_usage_errors_and_help_keep_the_binarys_codes(tmp_path):
    assert cli("run", "--jobs", "0", str(SMALL), cwd=tmp_path).returncode == 2
    assert cli("no-such-command", cwd=tmp_path).returncode == 2
    helped = cli("--help", cwd=tmp_path)
    assert helped.returncode == 0 and "Usage: kodama-dag" in helped.stdout
    version = cli("--version", cwd=tmp_path)
    assert version.returncode == 0 and kodama_dag.__version__ in version.stdout


def test_kinds_lists_the_same_kinds_as_the_api(tmp_path):
    r = cli("kinds", cwd=tmp_path)
    assert r.returncode == 0
    for name in ["SynthCity", "RasterizeSurface", "RegisterViews"]:
        assert name in kodama_dag.kinds() and name in r.stdout
