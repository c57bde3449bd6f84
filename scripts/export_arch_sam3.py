#!/usr/bin/env python3
"""Architectural and clutter instances for street views from SAM 3's text prompts, as the paper
runs it (Sec. 4.2.1), written as arch/<id>.png + arch/<id>.json and clutter/<id>.png +
clutter/<id>.json in the layout ReadViews and ReadViewOutputs read (README, "Models for real
imagery"; `nodes/src/io/views_io.rs`): a 16-bit PNG of instance ids at the view's size (0 = none)
and beside it {"<instance id>": "<class>"}.

The prompts and the class each gives are a label table, `graphs/labels/sam3_prompts.ron` by
default (`--table` for your own; same format as the tables SegmentViews reads). Every prompt's
every mask above the confidence threshold is one instance of the prompt's class, in the arch layer
for wall, roof, window, door, balcony, drainpipe, in the clutter layer for the others. Within a
layer a pixel that several masks cover keeps the mask of the prompt listed last, and within one
prompt the higher-scoring mask; an instance left with fewer than `--min-pixels` pixels (default
16) is dropped, its pixels left unlabelled, as SegmentViews drops small regions. SAM 3 is the one published image model found that gives
drainpipes (by the prompts "drainpipe" and "downspout"); no fixed-class façade model has them.

    # SAM 3: clone github.com/facebookresearch/sam3 and install it as its README says (PyTorch
    # >= 2.7 and a CUDA GPU); the checkpoint is facebook/sam3 on Hugging Face (whether it asks
    # you to accept a licence first: not checked).
    pip install numpy pillow
    python3 scripts/export_arch_sam3.py --views mapillary_views/views.json --out view_outputs
    python3 scripts/export_arch_sam3.py --self-test

API used, from the sam3 README's image example and sam3/model/sam3_image_processor.py (read with
the search tool, not run here: no GPU or weights on the machine this was written on):
`model = build_sam3_image_model()`, `processor = Sam3Processor(model)`,
`state = processor.set_image(pil_image)`, `out = processor.set_text_prompt(state=state,
prompt=text)`, then out["masks"] (bool, [N, 1, H, W] at the image's size), out["scores"] ([N]);
the processor keeps masks scoring over its `confidence_threshold` (0.5 by default; `--threshold`
sets it). Each prompt overwrites the previous one's results in `state`, so they are copied out
at once.

`--self-test` needs neither SAM 3 nor torch: it reads the shipped prompt table, paints synthetic
masks by the rules above, writes the PNG and JSON and reads them back (with Pillow when it is
importable, else with this script's own PNG reader).
"""

import argparse
import json
import os
import re
import struct
import sys
import zlib

import numpy as np

# Our vocabulary: nodes/src/stages/models/segment_views.rs, ARCH_CLASSES and CLUTTER_CLASSES.
ARCH_CLASSES = ["wall", "roof", "window", "door", "balcony", "drainpipe"]
CLUTTER_CLASSES = [
    "car", "van", "bus", "truck", "bicycle", "person", "pole", "sign", "traffic light", "bench",
    "shelter", "hydrant", "tree", "vegetation",
]
HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_TABLE = os.path.join(HERE, "..", "graphs", "labels", "sam3_prompts.ron")


def read_table(path):
    """The label table at `path`: [(prompt, our class or None)] in order. A reader for the tables'
    plain shape (`(model: "...", classes: [("a", Some("b")), ("c", None), ...])`, `//` comments),
    not for RON in general."""
    with open(path) as f:
        text = re.sub(r"//[^\n]*", "", f.read())
    body = re.search(r"classes\s*:\s*\[(.*)\]", text, re.S)
    if not body:
        raise SystemExit(f"{path}: expected `classes: [...]`")
    entry = r'\(\s*"([^"]*)"\s*,\s*(?:None|Some\(\s*"([^"]*)"\s*\))\s*\)'
    classes = [(m.group(1), m.group(2)) for m in re.finditer(entry, body.group(1))]
    leftover = re.sub(entry, "", body.group(1)).replace(",", "").strip()
    if leftover or not classes:
        raise SystemExit(f"{path}: could not read the classes near {leftover[:40]!r}")
    for prompt, ours in classes:
        if ours is not None and ours not in ARCH_CLASSES + CLUTTER_CLASSES:
            raise SystemExit(f"{path}: {prompt!r} -> {ours!r} is not one of our classes")
    return classes


def layer_of(cls):
    return "arch" if cls in ARCH_CLASSES else "clutter"


def paint(h, w, detections, min_pixels=16):
    """Instance layers from detections [(table index, class, score, bool mask [h, w])]:
    {"arch": (ids uint16 [h, w], {id: class}), "clutter": (...)}. Later table entries paint over
    earlier ones, and within an entry higher scores over lower; instances with fewer than
    `min_pixels` pixels left are dropped; ids are 1, 2, ... in painting order of the survivors."""
    out = {}
    for layer in ("arch", "clutter"):
        dets = [d for d in detections if layer_of(d[1]) == layer]
        dets.sort(key=lambda d: (d[0], d[2]))
        raw = np.zeros((h, w), np.int64)
        for k, (_, _, _, mask) in enumerate(dets, start=1):
            raw[np.asarray(mask, bool)] = k
        counts = np.bincount(raw.ravel(), minlength=len(dets) + 1)
        keep = [k for k in range(1, len(dets) + 1) if counts[k] >= min_pixels]
        if len(keep) > 65535:
            raise SystemExit(f"{len(keep)} {layer} instances: a layer holds 65535; raise --min-pixels")
        new = np.zeros(len(dets) + 1, np.uint16)
        for i, k in enumerate(keep, start=1):
            new[k] = i
        out[layer] = (new[raw], {i: dets[k - 1][1] for i, k in enumerate(keep, start=1)})
    return out


def png16(ids):
    """A 16-bit greyscale PNG of `ids` [h, w] (samples big-endian, filter 0 on every row)."""
    h, w = ids.shape
    raw = b"".join(b"\0" + ids[y].astype(">u2").tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def read_png16(data):
    """Reads back what png16 writes (and only that)."""
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (n,) = struct.unpack_from(">I", data, pos)
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour = struct.unpack_from(">IIBB", body)
            assert (depth, colour) == (16, 0), "16-bit greyscale only"
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    rows = [raw[y * (1 + 2 * w) : (y + 1) * (1 + 2 * w)] for y in range(h)]
    assert all(r[0] == 0 for r in rows), "filter 0 only"
    return np.stack([np.frombuffer(r[1:], ">u2") for r in rows]).astype(np.uint16)


def write_layer(out_dir, layer, vid, ids, classes):
    """<out>/<layer>/<id>.png and .json as views_io.rs reads them."""
    d = os.path.join(out_dir, layer)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, f"{vid}.png"), "wb") as f:
        f.write(png16(ids))
    with open(os.path.join(d, f"{vid}.json"), "w") as f:
        json.dump({str(k): c for k, c in sorted(classes.items())}, f, indent=1)


def run(args):
    import torch  # noqa: F401  (SAM 3 needs it; imported first for a clear error)
    from PIL import Image
    from sam3.model.sam3_image_processor import Sam3Processor
    from sam3.model_builder import build_sam3_image_model

    table = [(i, p, c) for i, (p, c) in enumerate(read_table(args.table)) if c is not None]
    processor = Sam3Processor(build_sam3_image_model())
    if hasattr(processor, "set_confidence_threshold"):
        processor.set_confidence_threshold(args.threshold)
    else:
        processor.confidence_threshold = args.threshold
    with open(args.views) as f:
        doc = json.load(f)
    views = doc["views"] if isinstance(doc, dict) else doc
    root = os.path.dirname(os.path.abspath(args.views))
    for v in views:
        vid, W, H = str(v["id"]), int(v["width"]), int(v["height"])
        image = Image.open(os.path.join(root, v["image"])).convert("RGB")
        if image.size != (W, H):
            raise SystemExit(f"view {vid}: image is {image.size}, views.json says {(W, H)}")
        state = processor.set_image(image)
        detections = []
        for i, prompt, cls in table:
            out = processor.set_text_prompt(state=state, prompt=prompt)
            masks = out["masks"].detach().cpu().numpy().reshape(-1, H, W)
            scores = out["scores"].detach().float().cpu().numpy().reshape(-1)
            detections += [(i, cls, float(s), m) for s, m in zip(scores, masks)]
        layers = paint(H, W, detections, args.min_pixels)
        for layer, (ids, classes) in layers.items():
            write_layer(args.out, layer, vid, ids, classes)
        print(f"{vid}: {len(layers['arch'][1])} arch, {len(layers['clutter'][1])} clutter instances")


def self_test():
    table = read_table(DEFAULT_TABLE)
    ours = {c for _, c in table if c}
    assert len(table) == 24 and ours == set(ARCH_CLASSES + CLUTTER_CLASSES), (len(table), ours)
    index = {p: i for i, (p, _) in enumerate(table)}

    h, w = 20, 30
    box = lambda y0, y1, x0, x1: np.pad(np.ones((y1 - y0, x1 - x0), bool), ((y0, h - y1), (x0, w - x1)))
    facade = box(0, 20, 0, 30)
    dets = [
        (index["window"], "window", 0.9, box(2, 8, 2, 8)),
        (index["building facade"], "wall", 0.8, facade),  # listed first: windows paint over it
        (index["drainpipe"], "drainpipe", 0.7, box(0, 20, 20, 22)),
        (index["downspout"], "drainpipe", 0.6, box(0, 20, 20, 21)),  # later prompt wins its column
        (index["door"], "door", 0.95, box(10, 20, 10, 11)),  # 10 pixels: under 16, dropped
        (index["car"], "car", 0.6, box(14, 20, 0, 12)),
        (index["car"], "car", 0.9, box(14, 20, 8, 16)),  # higher score wins the overlap
    ]
    layers = paint(h, w, dets, min_pixels=16)
    ids, cls = layers["arch"]
    assert cls == {1: "wall", 2: "window", 3: "drainpipe", 4: "drainpipe"}, cls
    assert ids[5, 5] == 2 and ids[0, 0] == 1 and ids[10, 10] == 0  # a dropped instance: none, as in SegmentViews
    assert ids[5, 20] == 4 and ids[5, 21] == 3
    cids, ccls = layers["clutter"]
    assert ccls == {1: "car", 2: "car"} and cids[15, 9] == 2 and cids[15, 2] == 1 and cids[0, 0] == 0

    tmp = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"kodama_sam3_selftest_{os.getpid()}")
    write_layer(tmp, "arch", "v0", ids, cls)
    with open(os.path.join(tmp, "arch", "v0.png"), "rb") as f:
        data = f.read()
    assert np.array_equal(read_png16(data), ids)
    reader = "this script's reader"
    try:
        from PIL import Image

        back = np.asarray(Image.open(os.path.join(tmp, "arch", "v0.png")))
        assert back.shape == (h, w) and np.array_equal(back.astype(np.uint16), ids), back.dtype
        reader = "Pillow"
    except ImportError:
        pass
    with open(os.path.join(tmp, "arch", "v0.json")) as f:
        table_back = json.load(f)
    assert table_back == {"1": "wall", "2": "window", "3": "drainpipe", "4": "drainpipe"}
    for name in ("v0.png", "v0.json"):
        os.remove(os.path.join(tmp, "arch", name))
    os.rmdir(os.path.join(tmp, "arch"))
    os.rmdir(tmp)
    print(f"self-test passed (table, painting order, small instances, PNG read back by {reader})")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--self-test", action="store_true", help="check the pure parts; no SAM 3 needed")
    ap.add_argument("--table", default=DEFAULT_TABLE, help="prompt table (default sam3_prompts.ron)")
    ap.add_argument("--views", help="views.json of the view folder whose images to run on")
    ap.add_argument("--out", help="output folder; arch/ and clutter/ are written in it")
    ap.add_argument("--threshold", type=float, default=0.5, help="SAM 3 confidence threshold")
    ap.add_argument("--min-pixels", type=int, default=16, help="smallest instance kept")
    args = ap.parse_args()
    if args.self_test:
        self_test()
        return
    if not (args.views and args.out):
        ap.error("give --self-test, or --views and --out")
    run(args)


if __name__ == "__main__":
    sys.exit(main())
