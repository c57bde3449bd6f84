#!/usr/bin/env python3
"""Surface normals for street views from Metric3D v2's ONNX export, written as
`normal/<id>.exr` in the layout ReadViews and ReadViewOutputs read (README, "Models for real
imagery"; `nodes/src/io/views_io.rs`).

What the twin reads: per pixel a unit normal in the view's camera frame, OpenCV's (x right, y
down, z forward), pointing out of the surface toward the camera (a wall seen head-on is
(0, 0, -1), the street under the camera about (0, -1, 0)); channels R, G, B = x, y, z, 32-bit
float, at the view's size. SynthViews writes its normals the same way.

The model: Metric3D v2 (Hu et al., TPAMI 2024, YvanYin/Metric3D), exported to ONNX with dynamic
shapes and its normal head by the Transformers.js maintainers (github.com/YvanYin/Metric3D,
issue 117, linked from its README): huggingface.co/onnx-community/metric3d-vit-small, -large or
-giant2, file onnx/model.onnx (fp32) or onnx/model_fp16.onnx. Its preprocessor_config.json
says: RGB, resized keeping the aspect ratio to about 518 pixels with sides a multiple of 14,
bicubic, neither rescaled nor normalised (the export normalises inside the graph), which is what
this script feeds it (`--normalize imagenet` for an export that does not).

    pip install onnxruntime numpy pillow          # OpenEXR optional: only the self-test reads EXR
    python3 scripts/export_normals_metric3d.py --list-outputs --model model.onnx
    python3 scripts/export_normals_metric3d.py --model model.onnx \\
        --views mapillary_views/views.json --out view_outputs
    python3 scripts/export_normals_metric3d.py --self-test

`--views` is a view folder's views.json (`"views": "mapillary"` among a graph's outputs writes
one, with `img/<id>.png` at the size the twin uses); `--out` the folder ReadViewOutputs reads
(`normal/` is made in it).

NOT RUN against the model: no weights on the machine this was written on. Unverified, and
checked at run time instead:
- the names of the outputs: the normal output is the one of shape [1, 3, h, w] or [1, 4, h, w]
  (Metric3D's normal head gives 3 components and a confidence; `--normal-output NAME` picks one),
  the depth output the one of shape [1, 1, h, w] or [1, h, w] (`--list-outputs` prints them);
- the normals' axes: the ONNX export's frame is not documented. Metric3D's normals are in the
  camera frame (its authors, issue 125) and DSINE's, from the same line of work, are (right,
  down, front) with a wall facing the camera at +z (issue 12 of baegwangbin/DSINE), which is
  ours up to a sign. So by default (`--frame auto`) the script fits the axes' signs: of the 8
  patterns, the one under which the model's normals agree best with normals taken from the
  model's own depth (cross product of the back-projected neighbours), over the views so far,
  and prints the agreement; `--frame +x+y+z` (or any signs) fixes them. A view that shows only
  walls cannot tell the sign of y (no surface faces up or down): the views' sum decides.
Every normal is then made unit length and turned to face the camera (a visible surface cannot
face away), and resized to the view bilinearly; a pixel with no valid normal is NaN (the relief
reads NaN as no normal, but a zero vector as a side face).

`--self-test` checks the pure parts on synthetic data, with no model and no weights: the frame
fit recovers a known sign pattern, the facing flip, the resize, and the EXR round trip (read
back with OpenEXR when it is importable, else with this script's own reader).
"""

import argparse
import json
import os
import struct
import sys

import numpy as np

# The eight sign patterns of the three axes, as (sx, sy, sz).
PATTERNS = [(sx, sy, sz) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]


def pattern_name(p):
    return "".join(("+" if s > 0 else "-") + a for s, a in zip(p, "xyz"))


def parse_frame(text):
    """'+x+y+z', '-x+y-z' ... -> (sx, sy, sz); 'auto' -> None."""
    if text == "auto":
        return None
    t = text.replace(" ", "").replace(",", "")
    if len(t) != 6 or [t[1], t[3], t[5]] != ["x", "y", "z"] or any(c not in "+-" for c in t[::2]):
        raise ValueError(f"--frame: expected auto or signs like +x-y-z, got {text!r}")
    return tuple(1 if c == "+" else -1 for c in t[::2])


# ---------------------------------------------------------------------------------------------
# Geometry (pure numpy)


def pixel_rays(h, w, fx, fy, cx, cy):
    """Per pixel (centre at i + 0.5, j + 0.5) the camera-frame direction (x, y, 1), [h, w, 3]."""
    u = (np.arange(w, dtype=np.float64) + 0.5 - cx) / fx
    v = (np.arange(h, dtype=np.float64) + 0.5 - cy) / fy
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu, vv, np.ones_like(uu)], axis=-1)


def unit(n):
    """Rows of n made unit length; zero or non-finite vectors become NaN."""
    n = np.asarray(n, dtype=np.float64)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = n / length
    bad = ~np.isfinite(out).all(axis=-1) | (length[..., 0] == 0)
    out[bad] = np.nan
    return out


def face_camera(n, rays):
    """Normals turned to face the camera: those with n . ray > 0 (facing away) are negated."""
    away = (n * rays).sum(axis=-1) > 0
    out = n.copy()
    out[away] = -out[away]
    return out


def normals_from_depth(depth, fx, fy, cx, cy):
    """Camera-frame normals facing the camera from a depth map (along the optical axis), by the
    cross product of central differences of the back-projected points; NaN at the border and
    where the depth is not finite and positive."""
    h, w = depth.shape
    d = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(np.float64)
    rays = pixel_rays(h, w, fx, fy, cx, cy)
    p = rays * d[..., None]
    du = np.full_like(p, np.nan)
    dv = np.full_like(p, np.nan)
    du[:, 1:-1] = p[:, 2:] - p[:, :-2]
    dv[1:-1, :] = p[2:, :] - p[:-2, :]
    # x right, y down: du x dv points away from the camera; negate to face it.
    n = -np.cross(du, dv)
    return face_camera(unit(n), rays)


def frame_scores(model_n, depth_n):
    """Sum over pixels where both are finite of (s * model_n) . depth_n, per sign pattern s in
    PATTERNS, and the number of such pixels."""
    ok = np.isfinite(model_n).all(axis=-1) & np.isfinite(depth_n).all(axis=-1)
    a, b = model_n[ok], depth_n[ok]
    prod = a * b  # [k, 3]: per-axis products; a pattern only changes their signs
    per_axis = prod.sum(axis=0)
    scores = [float(sx * per_axis[0] + sy * per_axis[1] + sz * per_axis[2]) for sx, sy, sz in PATTERNS]
    return scores, int(ok.sum())


def to_ours(model_n, signs, rays):
    """The model's normals [h, w, 3] under the axis signs `signs` in our convention: unit, in
    OpenCV's camera frame, facing the camera."""
    n = unit(model_n * np.asarray(signs, dtype=np.float64))
    return face_camera(n, rays)


def resize_bilinear(img, h, w):
    """[H, W, C] -> [h, w, C], bilinear with pixel centres aligned (align_corners=False), edges
    clamped."""
    H, W = img.shape[:2]
    ys = np.clip((np.arange(h) + 0.5) * H / h - 0.5, 0, H - 1)
    xs = np.clip((np.arange(w) + 0.5) * W / w - 0.5, 0, W - 1)
    y0 = np.floor(ys).astype(int)
    x0 = np.floor(xs).astype(int)
    y1 = np.minimum(y0 + 1, H - 1)
    x1 = np.minimum(x0 + 1, W - 1)
    fy = (ys - y0)[:, None, None]
    fx = (xs - x0)[None, :, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bottom = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return top * (1 - fy) + bottom * fy


def model_size(h, w, target=518, multiple=14):
    """The input size of the DPT preprocessor in onnx-community's preprocessor_config.json
    (keep_aspect_ratio, ensure_multiple_of 14, size 518 x 518): one scale for both sides, the one
    of the two closer to 1, each side then rounded to the nearest multiple of 14 (at least 14)."""
    sh, sw = target / h, target / w
    s = sw if abs(1 - sw) < abs(1 - sh) else sh
    rnd = lambda x: max(multiple, int(round(x / multiple)) * multiple)
    return rnd(s * h), rnd(s * w)


# ---------------------------------------------------------------------------------------------
# OpenEXR, uncompressed scanlines of 32-bit float channels (pure Python + numpy)


def _attr(name, kind, payload):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(payload)) + payload


def exr_bytes(channels, w, h):
    """An OpenEXR file holding `channels` ({name: [h, w] float array}), uncompressed, one
    scanline per block, increasing y."""
    names = sorted(channels)
    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for n in names) + b"\0"
    box = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = (
        struct.pack("<ii", 20000630, 2)
        + _attr("channels", "chlist", chlist)
        + _attr("compression", "compression", b"\0")
        + _attr("dataWindow", "box2i", box)
        + _attr("displayWindow", "box2i", box)
        + _attr("lineOrder", "lineOrder", b"\0")
        + _attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
        + _attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
        + _attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
        + b"\0"
    )
    planes = [np.ascontiguousarray(channels[n], dtype="<f4").reshape(h, w) for n in names]
    line_bytes = 4 * w * len(names)
    first = len(header) + 8 * h
    offsets = struct.pack(f"<{h}Q", *[first + y * (8 + line_bytes) for y in range(h)])
    blocks = b"".join(
        struct.pack("<ii", y, line_bytes) + b"".join(p[y].tobytes() for p in planes) for y in range(h)
    )
    return header + offsets + blocks


def read_exr_uncompressed(data):
    """Reads back what exr_bytes writes (and only that): ({name: [h, w] float32}, w, h)."""
    if struct.unpack_from("<i", data, 0)[0] != 20000630:
        raise ValueError("not an OpenEXR file")
    pos, attrs = 8, {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        kend = data.index(b"\0", end + 1)
        (size,) = struct.unpack_from("<i", data, kend + 1)
        attrs[name] = data[kend + 5 : kend + 5 + size]
        pos = kend + 5 + size
    pos += 1
    if attrs["compression"] != b"\0":
        raise ValueError("compressed EXR: this reader reads uncompressed files only")
    x0, y0, x1, y1 = struct.unpack("<iiii", attrs["dataWindow"])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    names, cl = [], attrs["channels"]
    while cl[0] != 0:
        end = cl.index(b"\0")
        names.append(cl[:end].decode())
        cl = cl[end + 17 :]
    offsets = struct.unpack_from(f"<{h}Q", data, pos)
    out = {n: np.zeros((h, w), np.float32) for n in names}
    for off in offsets:
        y, size = struct.unpack_from("<ii", data, off)
        line = np.frombuffer(data, "<f4", size // 4, off + 8).reshape(len(names), w)
        for k, n in enumerate(names):
            out[n][y - y0] = line[k]
    return out, w, h


def write_normal_exr(path, normals):
    """normal/<id>.exr: channels R, G, B = x, y, z of [h, w, 3] camera-frame normals."""
    h, w = normals.shape[:2]
    n = normals.astype(np.float32)
    data = exr_bytes({"R": n[..., 0], "G": n[..., 1], "B": n[..., 2]}, w, h)
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def read_exr_any(path):
    """{name: [h, w]} through OpenEXR when importable (an independent reader), else ours."""
    try:
        import OpenEXR  # noqa: F401
    except ImportError:
        with open(path, "rb") as f:
            return read_exr_uncompressed(f.read())[0], "this script's reader"
    import OpenEXR

    if hasattr(OpenEXR, "File"):  # OpenEXR >= 3.3; without separate_channels it joins R, G, B
        with OpenEXR.File(path, separate_channels=True) as f:
            chans = f.channels()
            return {k: np.asarray(v.pixels, np.float32) for k, v in chans.items()}, "OpenEXR"
    import Imath

    f = OpenEXR.InputFile(path)
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    ft = Imath.PixelType(Imath.PixelType.FLOAT)
    return {
        k: np.frombuffer(f.channel(k, ft), np.float32).reshape(h, w) for k in f.header()["channels"]
    }, "OpenEXR"


# ---------------------------------------------------------------------------------------------
# The views and the model


def view_intrinsics(v):
    """(fx, fy, cx, cy) of a views.json entry: {fx, fy, cx, cy} or {hfov_deg}, as views_io.rs."""
    k = v["intrinsics"]
    if all(key in k for key in ("fx", "fy", "cx", "cy")):
        return float(k["fx"]), float(k["fy"]), float(k["cx"]), float(k["cy"])
    f = v["width"] / 2.0 / np.tan(np.radians(float(k["hfov_deg"])) / 2.0)
    return f, f, v["width"] / 2.0, v["height"] / 2.0


def load_views(views_json):
    with open(views_json) as f:
        doc = json.load(f)
    views = doc["views"] if isinstance(doc, dict) else doc
    return views, os.path.dirname(os.path.abspath(views_json))


def pick_outputs(outputs, names, normal_name, depth_name=None):
    """(normal [C, h, w] with C >= 3, depth [h, w] or None) among the model's outputs: the ones
    named, else the one normal-shaped output, and the single-plane output whose name says depth
    (else the first single-plane one: a confidence map is single-plane too)."""
    arrays = dict(zip(names, outputs))
    if normal_name:
        normal = arrays[normal_name]
    else:
        cands = [n for n, a in arrays.items() if a.ndim == 4 and a.shape[0] == 1 and a.shape[1] in (3, 4)]
        if len(cands) != 1:
            shapes = {n: a.shape for n, a in arrays.items()}
            raise SystemExit(f"cannot tell the normal output among {shapes}: name it with --normal-output")
        normal = arrays[cands[0]]
    if depth_name:
        return normal[0], arrays[depth_name].reshape(arrays[depth_name].shape[-2:])
    planes = [n for n, a in arrays.items() if (a.ndim == 4 and a.shape[:2] == (1, 1)) or (a.ndim == 3 and a.shape[0] == 1)]
    planes.sort(key=lambda n: "depth" not in n.lower())
    depth = arrays[planes[0]].reshape(arrays[planes[0]].shape[-2:]) if planes else None
    return normal[0], depth


def run(args):
    import onnxruntime as ort
    from PIL import Image

    sess = ort.InferenceSession(args.model, providers=ort.get_available_providers())
    names = [o.name for o in sess.get_outputs()]
    if args.list_outputs:
        for i in sess.get_inputs():
            print(f"input  {i.name} {i.shape} {i.type}")
        for o in sess.get_outputs():
            print(f"output {o.name} {o.shape} {o.type}")
        return
    views, root = load_views(args.views)
    fixed = parse_frame(args.frame)
    totals, count = np.zeros(len(PATTERNS)), 0
    mean = np.array([0.485, 0.456, 0.406]) * 255
    std = np.array([0.229, 0.224, 0.225]) * 255
    for v in views:
        vid, W, H = str(v["id"]), int(v["width"]), int(v["height"])
        img = Image.open(os.path.join(root, v["image"])).convert("RGB")
        if img.size != (W, H):
            raise SystemExit(f"view {vid}: image is {img.size}, views.json says {(W, H)}")
        h, w = model_size(H, W, args.size)
        x = np.asarray(img.resize((w, h), Image.BICUBIC), dtype=np.float32)
        if args.normalize == "imagenet":
            x = (x - mean) / std
        x = x.transpose(2, 0, 1)[None].astype(np.float32)
        out = sess.run(None, {sess.get_inputs()[0].name: x})
        normal, depth = pick_outputs(out, names, args.normal_output, args.depth_output)
        if normal.shape[1:] != (h, w):
            raise SystemExit(f"view {vid}: normal output {normal.shape}, expected [C, {h}, {w}]")
        n_model = normal[:3].transpose(1, 2, 0).astype(np.float64)
        fx, fy, cx, cy = view_intrinsics(v)
        sx, sy = w / W, h / H
        k = (fx * sx, fy * sy, cx * sx, cy * sy)
        rays = pixel_rays(h, w, *k)
        if fixed is None:
            if depth is None or depth.shape != (h, w):
                raise SystemExit("--frame auto needs the model's depth at the normals' size; give --frame")
            scores, m = frame_scores(unit(n_model), normals_from_depth(depth, *k))
            totals += scores
            count += m
            best = int(np.argmax(totals))
            own = int(np.argmax(scores))
            note = "" if own == best else f" (this view alone: {pattern_name(PATTERNS[own])})"
            print(
                f"{vid}: frame {pattern_name(PATTERNS[best])}, mean agreement with the depth's "
                f"normals {totals[best] / max(count, 1):.3f}{note}"
            )
            signs = PATTERNS[best]
        else:
            signs = fixed
        ours = to_ours(n_model, signs, rays)
        ours = resize_bilinear(np.nan_to_num(ours), H, W)
        ours = face_camera(unit(ours), pixel_rays(H, W, fx, fy, cx, cy))
        # NaN where there is no normal: the relief reads NaN as no normal, a zero vector as a
        # side face.
        write_normal_exr(os.path.join(args.out, "normal", f"{vid}.exr"), ours)


# ---------------------------------------------------------------------------------------------
# Self-test


def self_test():
    rng = np.random.default_rng(7)
    h, w, f = 48, 64, 60.0
    cx, cy = w / 2, h / 2
    rays = pixel_rays(h, w, f, f, cx, cy)
    # A scene in OpenCV's frame: a wall 10 m ahead turned 30 degrees about the vertical (left
    # half), the street 1.5 m under the camera (bottom rows), each pixel's depth along z.
    t = np.radians(30)
    wall_n = np.array([np.sin(t), 0.0, -np.cos(t)])  # faces the camera, leans left
    wall_p = np.array([0.0, 0.0, 10.0])
    ground_n = np.array([0.0, -1.0, 0.0])  # up is -y
    ground_p = np.array([0.0, 1.5, 0.0])
    depth = np.full((h, w), np.nan)
    truth = np.full((h, w, 3), np.nan)
    for n, p in ((wall_n, wall_p), (ground_n, ground_p)):
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (p @ n) / (rays @ n)
        hit = np.isfinite(z) & (z > 0) & ((np.isnan(depth)) | (z < depth))
        depth[hit] = z[hit]
        truth[hit] = n
    assert np.isfinite(depth).mean() > 0.9, "synthetic scene covers the view"

    # Depth normals agree with the truth away from the seam between the planes.
    dn = normals_from_depth(depth, f, f, cx, cy)
    ok = np.isfinite(dn).all(-1) & np.isfinite(truth).all(-1)
    cos = (dn[ok] * truth[ok]).sum(-1)
    assert np.median(cos) > 0.999, f"depth normals: median cos {np.median(cos)}"

    # A model that reports OpenGL axes (x right, y up, z backward), with noise: the fit finds
    # signs (+, -, -), which bring its normals back to ours.
    opengl = truth * np.array([1.0, -1.0, -1.0]) + rng.normal(0, 0.05, truth.shape)
    scores, m = frame_scores(unit(opengl), dn)
    best = PATTERNS[int(np.argmax(scores))]
    assert best == (1, -1, -1), f"frame fit: {pattern_name(best)}"
    assert m > 0.8 * h * w
    ours = to_ours(opengl, best, rays)
    cos = (ours[ok] * truth[ok]).sum(-1)
    assert np.median(cos) > 0.99, f"converted normals: median cos {np.median(cos)}"
    # Every normal faces the camera; a normal given facing away is turned round.
    assert ((ours * rays).sum(-1)[ok] <= 0).all()
    away = to_ours(-truth, (1, 1, 1), rays)
    assert np.allclose(away[ok], truth[ok])
    assert parse_frame("+x-y-z") == (1, -1, -1) and parse_frame("auto") is None

    # Output picking: the normal-shaped output, and the depth by name before a confidence map.
    outs = [np.zeros((1, 1, 4, 5)), np.ones((1, 4, 4, 5)), np.full((1, 1, 4, 5), 2.0)]
    nrm, dep = pick_outputs(outs, ["confidence", "predicted_normal", "predicted_depth"], None)
    assert nrm.shape == (4, 4, 5) and nrm.max() == 1 and dep.shape == (4, 5) and dep.max() == 2

    # The DPT preprocessor's size for a 2048 x 1536 image: the short side to 518, multiples of 14.
    assert model_size(1536, 2048) == (518, 686), model_size(1536, 2048)
    # Bilinear resize keeps a constant field and a linear ramp.
    ramp = np.broadcast_to(np.arange(8, dtype=float)[None, :, None], (4, 8, 3))
    up = resize_bilinear(ramp, 8, 16)
    assert up.shape == (8, 16, 3) and np.allclose(up[:, 1:-1, 0], (np.arange(1, 15) + 0.5) / 2 - 0.5)

    # EXR round trip: R, G, B = x, y, z, bit for bit.
    path = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"kodama_normal_selftest_{os.getpid()}.exr")
    field = ours.astype(np.float32)
    field[0, :3] = np.nan  # pixels without a normal stay NaN
    write_normal_exr(path, field)
    chans, reader = read_exr_any(path)
    for k, c in enumerate("RGB"):
        assert chans[c].shape == (h, w) and np.array_equal(chans[c], field[..., k], equal_nan=True), c
    with open(path, "rb") as fh:
        own, ww, hh = read_exr_uncompressed(fh.read())
    assert (ww, hh) == (w, h) and np.array_equal(own["B"], field[..., 2], equal_nan=True)
    os.remove(path)
    print(f"self-test passed (frame fit, facing, resize, model size; EXR read back by {reader})")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--self-test", action="store_true", help="check the pure parts; no model needed")
    ap.add_argument("--model", help="Metric3D v2 ONNX file (onnx-community/metric3d-vit-*/onnx/model.onnx)")
    ap.add_argument("--list-outputs", action="store_true", help="print the model's inputs and outputs")
    ap.add_argument("--views", help="views.json of the view folder whose images to run on")
    ap.add_argument("--out", help="output folder; normal/<id>.exr are written in it")
    ap.add_argument("--frame", default="auto", help="auto, or the model axes' signs, e.g. +x+y+z")
    ap.add_argument("--normal-output", help="the model output holding the normals")
    ap.add_argument("--depth-output", help="the model output holding the depth (for --frame auto)")
    ap.add_argument("--normalize", choices=["none", "imagenet"], default="none")
    ap.add_argument("--size", type=int, default=518, help="preprocessor target size (default 518)")
    args = ap.parse_args()
    if args.self_test:
        self_test()
        return
    if not args.model or not (args.list_outputs or (args.views and args.out)):
        ap.error("give --self-test, or --model with --list-outputs, or --model, --views and --out")
    run(args)


if __name__ == "__main__":
    sys.exit(main())
