"""Writes examples/quickstart.ipynb from examples/quickstart.py: the script's `# %%` cells as
notebook cells (`# %% [markdown]` cells as Markdown, their leading `# ` removed), no outputs.
The script is the source (CI runs it); `--check` exits 1 when the notebook is not what this
script would write, so the two cannot drift apart (python/tests/test_quickstart.py).

    python3 scripts/quickstart_notebook.py [--check]
"""
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "examples" / "quickstart.py"
NOTEBOOK = ROOT / "examples" / "quickstart.ipynb"


def cells(text: str) -> list[dict]:
    out: list[dict] = []
    kind, lines = None, []

    def flush():
        while lines and not lines[-1].strip():
            lines.pop()
        if kind is None or not lines:
            return
        if kind == "markdown":
            body = [l[2:] if l.startswith("# ") else l.lstrip("#") for l in lines]
            out.append({"cell_type": "markdown", "metadata": {}, "source": body})
        else:
            out.append({"cell_type": "code", "execution_count": None, "metadata": {},
                        "outputs": [], "source": lines[:]})

    for line in text.splitlines(keepends=True):
        if line.startswith("# %%"):
            flush()
            kind = "markdown" if "[markdown]" in line else "code"
            lines = []
        elif kind is not None:
            lines.append(line)
    flush()
    for k, c in enumerate(out):
        c["id"] = f"cell-{k}"  # nbformat 4.5 requires ids; stable ones keep --check exact
        if c["source"]:
            c["source"][-1] = c["source"][-1].rstrip("\n")
    return out


def notebook() -> str:
    nb = {
        "cells": cells(SCRIPT.read_text()),
        "metadata": {
            "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
            "language_info": {"name": "python"},
        },
        "nbformat": 4,
        "nbformat_minor": 5,
    }
    return json.dumps(nb, indent=1, ensure_ascii=False) + "\n"


def main() -> int:
    want = notebook()
    if "--check" in sys.argv[1:]:
        if not NOTEBOOK.is_file() or NOTEBOOK.read_text() != want:
            print(f"{NOTEBOOK} is not what {SCRIPT} gives: run python3 scripts/quickstart_notebook.py",
                  file=sys.stderr)
            return 1
        return 0
    NOTEBOOK.write_text(want)
    print(f"wrote {NOTEBOOK}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
