"""The quickstart (examples/quickstart.py) runs as a script. In CI it runs on the small
python/tests/quickstart.ron (the demo's node names, Sec. 4.1 only: seconds); on the demo it
is what the README's Python section shows, and takes the demo's minutes."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_quickstart_runs_as_a_script(tmp_path):
    env = dict(os.environ)
    env.update(
        KODAMA_QUICKSTART_GRAPH=str(ROOT / "python" / "tests" / "quickstart.ron"),
        KODAMA_QUICKSTART_OUT=str(tmp_path / "out"),
        KODAMA_DAG_CACHE=str(tmp_path / "cache"),
        MPLBACKEND="Agg",
    )
    r = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "quickstart.py")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "twin_eval" in r.stdout and "P2P RMSE" in r.stdout
    assert "radio map" in r.stdout and "path gain" in r.stdout
    # The radio map's figure (.ci/run installs matplotlib, as the test extras do).
    assert (tmp_path / "out" / "radio_map_quickstart.png").stat().st_size > 10_000
    assert (tmp_path / "out" / "twin.sionna" / "scene.xml").is_file()
    assert (tmp_path / "out" / "twin.sionna" / "site.json").is_file()
    # Four links traced from the map's centre, each with a finite gain or none at all.
    assert r.stdout.count("from the transmitter: path gain") == 4
    # The twin handed to Sionna RT in memory, its PathSolver on the same four links (.ci/run
    # installs sionna-rt; without it the script says so and this part is not checked).
    if os.environ.get("CI") == "true" or "Sionna RT scene in memory" in r.stdout:
        assert "Sionna RT scene in memory" in r.stdout, r.stderr
        assert r.stdout.count("Sionna RT") >= 5


def test_the_notebook_is_the_script_and_a_valid_notebook():
    r = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "quickstart_notebook.py"), "--check"],
        capture_output=True, text=True,
    )
    assert r.returncode == 0, r.stderr
    import nbformat  # .ci/run installs it

    nb = nbformat.read(ROOT / "examples" / "quickstart.ipynb", as_version=4)
    nbformat.validate(nb)
    code = "".join(c.source + "\n" for c in nb.cells if c.cell_type == "code")
    assert "kodama_dag.to_sionna(scene)" in code
