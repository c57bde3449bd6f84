#!/usr/bin/env python3
"""The ten longest functions and the ten longest source files of nodes/src.

Functions are counted from their `fn` line to their closing brace, inclusive (blank and comment
lines within them included); files by their code lines: lines that are not blank and not only a
comment, outside `#[cfg(test)]` modules. Test modules' functions are left out of both.

Usage: scripts/longest.py [ROOT] [-n N]   (ROOT defaults to nodes/src beside this script)
"""

import argparse
import re
from pathlib import Path

CHAR = re.compile(r"'(?:\\.|\\u\{[0-9a-fA-F]+\}|[^\\'\n])'")
FN = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:const\s+)?(?:async\s+)?(?:unsafe\s+)?"
                r"(?:extern\s+\"[^\"]*\"\s+)?fn\s+([A-Za-z_][A-Za-z0-9_]*)")


def clean(text):
    """The text with comments, strings and char literals blanked (newlines kept), so braces and
    `fn` are only the code's."""
    out = []
    i, n = 0, len(text)
    depth_block = 0
    while i < n:
        c = text[i]
        if depth_block:
            if text.startswith("*/", i):
                depth_block -= 1
                out.append("  ")
                i += 2
            elif text.startswith("/*", i):
                depth_block += 1
                out.append("  ")
                i += 2
            else:
                out.append("\n" if c == "\n" else " ")
                i += 1
            continue
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
            continue
        if text.startswith("/*", i):
            depth_block = 1
            out.append("  ")
            i += 2
            continue
        m = re.match(r'r(#*)"', text[i:i + 10]) if c == "r" and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")) else None
        if m:
            close = '"' + m.group(1)
            j = text.find(close, i + len(m.group(0)))
            j = n if j < 0 else j + len(close)
            out.append("".join("\n" if ch == "\n" else " " for ch in text[i:j]))
            i = j
            continue
        if c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append("".join("\n" if ch == "\n" else " " for ch in text[i:j]))
            i = j
            continue
        if c == "'":
            m = CHAR.match(text, i)
            if m:
                out.append(" " * (m.end() - i))
                i = m.end()
                continue
        out.append(c)
        i += 1
    return "".join(out)


def block_end(lines, start):
    """The line where the brace block opened at or after line `start` closes (None: no block, a
    declaration without a body)."""
    depth = 0
    opened = False
    nest = 0  # `(`, `[`, `<` nesting before the body opens: a `;` inside (`[f64; 2]`) is no end
    for k in range(start, len(lines)):
        line = lines[k]
        for i, ch in enumerate(line):
            if ch == "{":
                depth += 1
                opened = True
            elif ch == "}":
                depth -= 1
                if opened and depth == 0:
                    return k
            elif opened:
                continue
            elif ch in "([<":
                nest += 1
            elif ch in ")]" or (ch == ">" and not (i > 0 and line[i - 1] == "-")):
                nest = max(nest - 1, 0)
            elif ch == ";" and depth == 0 and nest == 0:
                return None
    return None


def test_spans(lines):
    """Line spans (inclusive) of `#[cfg(test)]` items."""
    spans = []
    for k, line in enumerate(lines):
        if line.strip().startswith("#[cfg(test)]"):
            end = block_end(lines, k)
            if end is not None:
                spans.append((k, end))
    return spans


def measure(root):
    functions, files = [], []
    for path in sorted(root.rglob("*.rs")):
        raw = path.read_text(encoding="utf-8")
        code = clean(raw).split("\n")
        spans = test_spans(code)
        in_test = [False] * len(code)
        for a, b in spans:
            for k in range(a, b + 1):
                in_test[k] = True
        rel = path.relative_to(root.parent.parent) if root.name == "src" else path
        code_lines = sum(1 for k, l in enumerate(code) if l.strip() and not in_test[k])
        all_lines = sum(1 for k in range(len(code)) if not in_test[k])
        files.append((code_lines, all_lines, str(rel)))
        for k, line in enumerate(code):
            m = FN.match(line)
            if not m or in_test[k]:
                continue
            end = block_end(code, k)
            if end is not None:
                functions.append((end - k + 1, f"{rel}:{k + 1}", m.group(1)))
    return functions, files


def main():
    here = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", nargs="?", default=str(here / "nodes" / "src"))
    ap.add_argument("-n", type=int, default=10)
    a = ap.parse_args()
    functions, files = measure(Path(a.root))
    print("Longest functions (lines, fn to closing brace, tests aside):")
    for lines, at, name in sorted(functions, key=lambda f: (-f[0], f[1]))[: a.n]:
        print(f"  {lines:5}  {name}  {at}")
    print("Longest files (code lines: not blank, not only a comment; all lines; tests aside):")
    for lines, total, rel in sorted(files, key=lambda f: (-f[0], f[2]))[: a.n]:
        print(f"  {lines:5}  {total:5}  {rel}")


if __name__ == "__main__":
    main()
