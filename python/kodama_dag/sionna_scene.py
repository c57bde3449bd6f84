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
