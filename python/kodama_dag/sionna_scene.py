"""`to_sionna`: a twin as a `sionna.rt.Scene` in memory, with no files in between.

The scene Sionna RT gets is the one `kodama-dag` exports as `.sionna` (nodes/src/io/sionna_xml.rs)
and `sionna.rt.load_scene(..., merge_shapes=False)` reads back: one object per scene object
(building, terrain, ...) and ITU-R P.2040 material, named `<object>-itu_<material>`; one
`ITURadioMaterial` per class, named `itu_<material>`, with the slab thickness our tracer gives its
transmission; face normals from the triangles' winding. Foliage has no P.2040 class and is left
out, as in the export (our tracer applies it as a volume loss).

Coordinates are the site frame (metres; x east, y north, z up): easting = x + origin[0], northing
= y + origin[1] in the site's CRS (`Run.site`, or `site.json` beside an export). UTM coordinates
themselves would lose centimetres in Sionna's float32 geometry.
"""

from __future__ import annotations

import json
import os
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from . import _core
from .radio import SceneLike

if TYPE_CHECKING:
    import sionna.rt


def _safe_name(object_id: str) -> str:
    """As the export names files: letters, digits, `-` and `_` kept, anything else `_`."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", object_id)


def _import_sionna():
    try:
        import mitsuba as mi
        import sionna.rt as rt
    except ImportError as e:
        raise ImportError(
            "to_sionna needs Sionna RT: pip install sionna-rt (on a CPU, Dr.Jit also needs "
            "libLLVM; docs/python.md, 'Sionna RT')"
        ) from e
    return mi, rt


def _mesh(mi: Any, name: str, vertices: np.ndarray, triangles: np.ndarray) -> Any:
    """A Mitsuba triangle mesh with face normals, as the `ply` plugin makes of our PLY files."""
    props = mi.Properties()
    props["face_normals"] = True
    mesh = mi.Mesh(name, len(vertices), len(triangles), props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.ascontiguousarray(vertices, np.float32).ravel())
    params["faces"] = mi.UInt32(np.ascontiguousarray(triangles, np.uint32).ravel())
    params.update()
    return mesh


def _parts(obj: dict[str, Any]):
    """`obj`'s triangles grouped by material code (ascending), each with only the vertices its
    triangles use, renumbered in first-use order (as the export writes them)."""
    materials = np.asarray(obj["materials"])
    triangles = np.asarray(obj["triangles"])
    vertices = np.asarray(obj["vertices"])
    for code in np.unique(materials):
        tris = triangles[materials == code]
        used, first = np.unique(tris.ravel(), return_index=True)
        order = used[np.argsort(first)]
        remap = np.empty(len(vertices), np.uint32)
        remap[order] = np.arange(len(order), dtype=np.uint32)
        yield int(code), vertices[order], remap[tris]


def to_sionna(scene: SceneLike) -> "sionna.rt.Scene":
    """The scene as a `sionna.rt.Scene` (module docs), ready for Sionna RT's `PathSolver` and
    `RadioMapSolver` once transmitters, receivers and arrays are added.

    `scene` is `(run, node)` for a Scene node of a finished run (built in memory), or a Sionna RT
    XML file (loaded with `merge_shapes=False`, so each building stays an object). Needs the
    `sionna-rt` package; raises ImportError without it."""
    mi, rt = _import_sionna()
    if not isinstance(scene, tuple):
        path = os.fspath(scene)
        if not os.path.isfile(path):
            raise _core.UserError(f"{path}: expected a Sionna RT scene file (scene.xml)")
        return rt.load_scene(path, merge_shapes=False)
    if len(scene) != 2:
        raise _core.UserError("scene: expected a file, or (run, node) for a run's scene node")
    run, node = scene
    objects = run.scene(node)
    materials: dict[int, Any] = {}
    shapes = []
    for obj in objects:
        names, thickness = obj["material_names"], obj["material_thickness_m"]
        for code, vertices, triangles in _parts(obj):
            itu = names[code]
            if itu == "foliage":
                continue
            if code not in materials:
                materials[code] = rt.ITURadioMaterial(
                    name=f"itu_{itu}", itu_type=itu, thickness=float(thickness[code])
                )
            name = f"{_safe_name(obj['id'])}-itu_{itu}"
            shapes.append(
                rt.SceneObject(
                    mi_mesh=_mesh(mi, name, vertices, triangles),
                    name=name,
                    radio_material=materials[code],
                )
            )
    out = rt.load_scene()
    if shapes:
        out.edit(add=shapes)
    return out


def sionna_foliage_loss_db(
    folder: "str | os.PathLike[str]",
    paths: Any,
    freq_hz: float,
    *,
    db_per_m: float | None = None,
    max_db: "float | str | None" = None,
) -> np.ndarray:
    """The foliage loss of each of Sionna RT's `paths`, dB, shaped as `paths.valid`
    ([num_rx, num_tx, num_paths]; 0 where a path is not valid): the metres each path runs inside
    the foliage volumes of a `.sionna` export (`foliage.json`, `foliage/*.ply`; none: all 0),
    measured as our tracer measures its own, times `db_per_m` (default ITU-R P.833 Figure 2 at
    `freq_hz`), or, with `max_db` (`"p833"` or A_m in dB), ITU-R P.833's saturating law. Sionna
    RT has no foliage material, so the paper applies this loss after tracing (Sec. 4.2.4, 5):
    multiply each path's `a` by `10 ** (-loss / 20)`, as `with_foliage` does."""
    folder = os.fspath(folder)
    meta = os.path.join(folder, "foliage.json")
    valid = np.asarray(paths.valid, dtype=bool)
    if valid.ndim != 3:
        raise _core.UserError(
            f"paths: expected Sionna RT Paths of single-antenna (synthetic) arrays, valid of shape "
            f"(num_rx, num_tx, num_paths); got {valid.shape}"
        )
    loss = np.zeros(valid.shape)
    if not os.path.isfile(meta):
        return loss
    with open(meta) as f:
        volumes = [os.path.join(folder, v) for v in json.load(f)["volumes"]]
    sources = np.asarray(paths.sources, dtype=np.float64).T  # (num_tx, 3)
    targets = np.asarray(paths.targets, dtype=np.float64).T  # (num_rx, 3)
    vertices = np.asarray(paths.vertices, dtype=np.float64)  # (depth, rx, tx, path, 3)
    interactions = np.asarray(paths.interactions)  # (depth, rx, tx, path)
    points, counts, where = [], [], []
    for r, t, k in zip(*np.nonzero(valid)):
        used = interactions[:, r, t, k] != 0
        chain = [sources[t], *vertices[used, r, t, k], targets[r]]
        points.extend(chain)
        counts.append(len(chain))
        where.append((r, t, k))
    if not counts:
        return loss
    lengths = _core.foliage_lengths(volumes, np.asarray(points, dtype=np.float64), counts)
    db = _core.foliage_loss_db(list(lengths), float(freq_hz), db_per_m, max_db)
    for (r, t, k), v in zip(where, db):
        loss[r, t, k] = v
    return loss


def with_foliage(paths: Any, loss_db: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sionna RT's `paths.a` (real, imaginary) as NumPy arrays with `loss_db`
    (`sionna_foliage_loss_db`) applied to each path."""
    re, im = (np.asarray(v) for v in paths.a)  # (rx, rx_ant, tx, tx_ant, path)
    amp = 10.0 ** (-loss_db / 20.0)[:, None, :, None, :]
    return re * amp, im * amp
