"""The add-on's logic without its UI: a mesh object's handles (Empties) as an edit, the deform through voxwarp's
Python module, and the result as a Blender mesh.

Frame: the mesh object's own (local) coordinates, in its own units. They are the coordinates voxwarp sees, an
exported edit file holds and an exported mesh is written in, so that `voxwarp deform` on the command line
reproduces a deform made here byte for byte.

A handle is an Empty parented to the mesh whose custom properties record what it is:
  voxwarp_kind   "handle" (a frame: its point and orientation), "pin" (hold a point) or "region" (a
                 sphere, radius = display size x scale: the material inside follows the Empty's rigid motion,
                 or is held still if the Empty has not moved). Any of them shown as a sphere (Empty display
                 "Sphere") is a region.
  voxwarp_rest   where the handle was put (location, 3 doubles) and its rotation then (quaternion w x y z)
  voxwarp_to     the exact target read from an edit file, used while the Empty stays where it was put
  voxwarp_weight optional weight (> 0) of its constraints
  voxwarp_point_only  a handle read from a file's "move": written back as a move while it is not turned
The Empty's current location and rotation are its target.
"""

import ctypes
import glob
import json
import math
import os
import re
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix, Quaternion, Vector

KIND, REST, TO, WEIGHT = "voxwarp_kind", "voxwarp_rest", "voxwarp_to", "voxwarp_weight"
POINT_ONLY = "voxwarp_point_only"  # a handle read from a file's "move": its orientation is free until it is turned
EXTRA = "voxwarp_extra"  # on the mesh object: JSON of what Empties cannot show (earlier edits, control points)
KINDS = ("handle", "pin", "region")
DISPLAY = {"handle": "ARROWS", "pin": "PLAIN_AXES", "region": "SPHERE"}

# ---- finding the compiled module ----------------------------------------------------------------------------------

_module = None


def module_folders(preference=""):
    """Folders that may hold the `voxwarp` package, in the order they are tried."""
    here = os.path.dirname(os.path.abspath(__file__))
    folders = [os.path.join(here, "lib")]  # shipped by blender/install.sh
    folders += [p for p in (preference, os.environ.get("VOXWARP_PYTHONPATH", "")) if p]
    source = os.path.dirname(os.path.dirname(here))  # run from the source tree: its build
    folders.append(os.path.join(source, "build", "python"))
    return folders


def module(preference=""):
    """voxwarp's Python module: the copy the add-on ships (blender/install.sh), else one in the preference's folder,
    VOXWARP_PYTHONPATH or the source tree's build, else one on sys.path. Raises RuntimeError saying how to install
    it when there is none."""
    global _module
    if _module is None and "voxwarp" in sys.modules:
        _module = sys.modules["voxwarp"]
    if _module is not None:
        return _module
    for folder in module_folders(preference):
        if not os.path.isfile(os.path.join(folder, "voxwarp", "__init__.py")):
            continue
        _preload(folder)
        sys.path.insert(0, folder)
        try:
            import voxwarp
        except ImportError as e:
            sys.path.remove(folder)
            raise RuntimeError(f"voxwarp's module in {folder} does not load in Blender's Python {sys.version.split()[0]}: {e}") from e
        _module = voxwarp
        return _module
    try:
        import voxwarp
    except ImportError:
        raise RuntimeError("voxwarp's Python module was not found (looked in " + ", ".join(module_folders(preference)) +
                           "): run `bash blender/install.sh` in voxwarp's source folder, or set the folder holding it "
                           "(build/python) in the add-on's preferences") from None
    _module = voxwarp
    return _module


def _preload(folder):
    """The shipped copy's own voxwarp libraries, loaded first, each after the ones it needs, so that the module
    finds them by name (not through the build tree its RUNPATH names, which may be gone)."""
    libraries = {os.path.basename(p): p for p in glob.glob(os.path.join(folder, "libvoxwarp_*.so"))}
    needs = {}
    for name, path in libraries.items():
        with open(path, "rb") as f:  # the names in its dynamic string table: its own and those it needs
            needs[name] = {n.decode() for n in re.findall(rb"libvoxwarp_\w+\.so", f.read())} - {name}
    loaded = set()
    while len(loaded) < len(libraries):
        ready = sorted(n for n in libraries if n not in loaded and needs[n] <= loaded | (needs[n] - set(libraries)))
        if not ready:
            return  # a cycle cannot happen between shared libraries that link; leave the rest to the loader
        for name in ready:
            ctypes.CDLL(libraries[name], mode=ctypes.RTLD_GLOBAL)
            loaded.add(name)


# ---- the source mesh as arrays --------------------------------------------------------------------------------------

def source_arrays(obj, depsgraph=None, modifiers=True):
    """The mesh object's evaluated mesh (modifiers applied; modifiers=False: its own mesh) as voxwarp's arrays in its
    local frame: V float64 (n, 3), F int32 (m, 3), and its attributes (UV map, custom split normals, colour,
    materials) as voxwarp.read_mesh gives them, or None."""
    if modifiers:
        evaluated = obj.evaluated_get(depsgraph or bpy.context.evaluated_depsgraph_get())
        me = evaluated.to_mesh()
    else:
        evaluated, me = None, obj.data
    try:
        me.calc_loop_triangles()
        n, m = len(me.vertices), len(me.loop_triangles)
        if n == 0 or m == 0:
            raise ValueError(f"{obj.name}: the mesh has no faces to deform")
        V = np.empty(3 * n, np.float32)
        me.vertices.foreach_get("co", V)
        F = np.empty(3 * m, np.int32)
        me.loop_triangles.foreach_get("vertices", F)
        loops = np.empty(3 * m, np.int32)
        me.loop_triangles.foreach_get("loops", loops)
        attributes = {}
        if me.uv_layers.active is not None:
            uv = np.empty(2 * len(me.loops), np.float32)
            me.uv_layers.active.data.foreach_get("uv", uv)
            corners = uv.reshape(-1, 2)[loops].astype(np.float64)
            unique, index = np.unique(corners, axis=0, return_inverse=True)
            attributes["uv"] = unique
            attributes["uv_index"] = index.reshape(-1, 3).astype(np.int32)
        if getattr(me, "has_custom_normals", False):
            # Shading the user set (hard edges, weighted or baked normals) is carried; a mesh without custom normals
            # gets the output's own shading instead.
            me.calc_normals_split()
            normal = np.empty(3 * len(me.loops), np.float32)
            me.loops.foreach_get("normal", normal)
            corners = normal.reshape(-1, 3)[loops].astype(np.float64)
            unique, index = np.unique(corners, axis=0, return_inverse=True)
            attributes["normal"] = unique
            attributes["normal_index"] = index.reshape(-1, 3).astype(np.int32)
        colour = _active_colour(me)
        if colour is not None:
            attributes["colour"] = colour
        if len(obj.material_slots) > 0:
            material = np.empty(m, np.int32)
            me.loop_triangles.foreach_get("material_index", material)
            attributes["material"] = np.minimum(material, len(obj.material_slots) - 1)
            attributes["materials"] = [{"name": s.material.name if s.material else f"slot{i}"} for i, s in enumerate(obj.material_slots)]
        return V.reshape(-1, 3).astype(np.float64), F.reshape(-1, 3), (attributes or None)
    finally:
        if evaluated is not None:
            evaluated.to_mesh_clear()


def _active_colour(me):
    """The active colour attribute as float32 (n, 3) per vertex in [0, 1] (sRGB, as files hold it), or None."""
    layer = getattr(me.color_attributes, "active_color", None) if hasattr(me, "color_attributes") else None
    if layer is None:
        return None
    field = "color_srgb" if hasattr(layer.data[0] if len(layer.data) else None, "color_srgb") else "color"
    rgba = np.empty(4 * len(layer.data), np.float32)
    layer.data.foreach_get(field, rgba)
    rgba = rgba.reshape(-1, 4)[:, :3]
    if layer.domain == "POINT":
        return np.clip(rgba, 0, 1)
    if layer.domain == "CORNER":
        vertex = np.empty(len(me.loops), np.int32)
        me.loops.foreach_get("vertex_index", vertex)
        total = np.zeros((len(me.vertices), 3), np.float64)
        count = np.zeros(len(me.vertices))
        np.add.at(total, vertex, rgba)
        np.add.at(count, vertex, 1)
        return np.clip(total / np.maximum(count, 1)[:, None], 0, 1).astype(np.float32)
    return None


# ---- handles --------------------------------------------------------------------------------------------------------

def is_handle(o):
    return o is not None and o.type == "EMPTY" and o.get(KIND) in KINDS


def kind_of(e):
    """What a handle does: an Empty shown as a sphere is a region, whatever it was added as."""
    return "region" if e.empty_display_type == "SPHERE" else e[KIND]


def handles(obj):
    """The mesh object's handles, in a stable order (by name)."""
    return sorted((c for c in obj.children if is_handle(c)), key=lambda o: o.name)


def source_of(o):
    """The mesh a selection refers to: the object itself, or a handle's mesh."""
    if is_handle(o) and o.parent is not None and o.parent.type == "MESH":
        return o.parent
    return o if o is not None and o.type == "MESH" else None


def handle_collection(obj):
    """The "voxwarp" collection under the mesh's collection, holding its handles."""
    parent = obj.users_collection[0] if obj.users_collection else bpy.context.scene.collection
    for c in parent.children:
        if c.name == "voxwarp" or c.name.startswith("voxwarp."):
            return c
    c = bpy.data.collections.new("voxwarp")
    parent.children.link(c)
    return c


def handle_size(obj, fraction):
    """A handle's display size: `fraction` of the mesh's bounding-box diagonal (its own frame)."""
    return (Vector(obj.bound_box[6]) - Vector(obj.bound_box[0])).length * fraction or fraction  # local bounds' max and min corners


def add_handle(obj, kind, location, size, target=None, weight=None):
    """A new handle of `kind` at `location` (local frame), resting there; `target` (local) moves it at once."""
    if kind not in KINDS:
        raise ValueError(f"handle kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    e = bpy.data.objects.new(f"{obj.name} {kind}", None)
    e.empty_display_type = DISPLAY[kind]
    e.empty_display_size = size
    handle_collection(obj).objects.link(e)
    e.parent = obj
    e.matrix_parent_inverse = Matrix.Identity(4)
    e[KIND] = kind
    e[REST] = [float(x) for x in location] + [1.0, 0.0, 0.0, 0.0]
    e.location = Vector(target if target is not None else location)
    e[TO] = [float(x) for x in (target if target is not None else location)]
    if weight is not None:
        e[WEIGHT] = float(weight)
    return e


def rest_of(e):
    """Where the handle rests: its location (3 doubles, exact as given) and rotation."""
    r = [float(x) for x in e[REST]]
    return r[:3], Quaternion(r[3:7])


def set_rest(e):
    """The handle's rest becomes where it is now (after the mesh itself was deformed in place)."""
    location, rotation = local_frame(e)
    e[REST] = [float(x) for x in location] + list(rotation)
    e[TO] = [float(x) for x in location]


def _local_matrix(e):
    """The handle's transform in its mesh's frame (its own, as parented by add_handle, or through the world)."""
    if e.matrix_parent_inverse == Matrix.Identity(4):
        return e.matrix_basis
    return e.parent.matrix_world.inverted_safe() @ e.matrix_world


def local_frame(e):
    """The handle's location and rotation in its mesh's frame (the location exact as set, when parented so)."""
    m = _local_matrix(e)
    location = e.location.copy() if e.matrix_parent_inverse == Matrix.Identity(4) else m.to_translation()
    return location, m.to_quaternion()


def _exact(e, location):
    """The handle's target: the exact doubles it was given while the Empty stays there, else its location."""
    to = e.get(TO)
    if to is not None and len(to) == 3 and Vector(list(to)) == location:
        return [float(x) for x in to]
    return [float(x) for x in location]


def _scale(e):
    return max(abs(s) for s in _local_matrix(e).to_scale())


def _rotate(turn, pivot=None):
    rotate = {"axis": [float(x) for x in turn.axis], "degrees": math.degrees(turn.angle)}
    if pivot is not None:
        rotate["pivot"] = pivot
    return rotate


def constraints_of(obj):
    """The edit-file entries the mesh's handles stand for (local frame): a handle is a frame (its point to the
    Empty's location, the map there turned as the Empty is; a handle read from a file's move stays a move until it
    is turned); a pin a pin; a region a region (a sphere), with the Empty's motion from its rest as its own."""
    out = []
    for e in handles(obj):
        kind = kind_of(e)
        exact_rest, rest_rotation = rest_of(e)
        rest = Vector(exact_rest)
        location, rotation = local_frame(e)
        to = _exact(e, location)
        turn = rotation @ rest_rotation.inverted()
        turned = abs(math.remainder(turn.angle, 2 * math.pi)) > 1e-6
        if kind == "pin":
            c = {"pin": to}
        elif kind == "handle" and e.get(POINT_ONLY) and not turned:
            c = {"move": exact_rest, "to": to}
        elif kind == "handle":
            c = {"frame": exact_rest, "to": to}
            if turned:
                c["rotate"] = _rotate(turn)
        else:
            c = {"region": {"sphere": [exact_rest, e.empty_display_size * _scale(e)]}}
            if Vector(to) != rest:
                c["translate"] = [float(t) - float(r) for t, r in zip(to, exact_rest)]
            if turned:
                c["rotate"] = _rotate(turn, exact_rest)
        if WEIGHT in e:
            c["weight"] = float(e[WEIGHT])
        out.append(c)
    return out


def extra_of(obj):
    """What an imported edit file held that Empties cannot show: {"earlier": [edits], "constraints": [...]}."""
    try:
        extra = json.loads(obj.get(EXTRA, "{}"))
    except ValueError:
        extra = {}
    return {"earlier": extra.get("earlier", []), "constraints": extra.get("constraints", [])}


def edit_of(obj, settings):
    """The edit (a dict in the edit-file schema) the mesh's handles and settings stand for."""
    extra = extra_of(obj)
    constraints = constraints_of(obj) + extra["constraints"]
    if not constraints:
        raise ValueError(f"{obj.name}: no handles: add a handle (and a pin or a region to hold what should stay)")
    return {
        "lattice": {"size": list(settings.lattice_size), "placement": settings.lattice_placement.lower(), "padding": settings.lattice_padding},
        "edits": extra["earlier"] + [{"solver": settings.solver.lower().replace("_", "-"), "preserve_volume": bool(settings.preserve_volume),
                                      "constraints": constraints}],
    }


def edit_text(edit):
    """An edit as the bundled edit files are laid out: one constraint a line, numbers exact (shortest round trip)."""
    lines = ["{", f'  "lattice": {json.dumps(edit["lattice"])},', '  "edits": [']
    for i, e in enumerate(edit["edits"]):
        head = json.dumps({k: v for k, v in e.items() if k != "constraints"})[1:-1]
        lines.append("    { " + (head + ", " if head else "") + '"constraints": [')
        lines += ["        " + json.dumps(c) + ("," if j + 1 < len(e["constraints"]) else "") for j, c in enumerate(e["constraints"])]
        lines.append("    ] }" + ("," if i + 1 < len(edit["edits"]) else ""))
    return "\n".join(lines + ["  ]", "}"]) + "\n"


def _turn(e, rotate):
    """The Empty turned by an edit file's rotation (about its own location)."""
    if rotate:
        e.rotation_mode = "QUATERNION"
        e.rotation_quaternion = Quaternion(Vector(rotate["axis"]).normalized(), math.radians(rotate["degrees"]))
        e.rotation_mode = "XYZ"


def import_edit(obj, edit, settings, size):
    """Handles for an edit file's last edit, already validated by voxwarp.read_edit: moves and frames become handles
    at their targets, turned as a frame says; pins pins; sphere regions sphere Empties moved and turned by their
    motion. Its lattice and solver go into the settings; earlier edits, control-point offsets, box regions, connects,
    normals and slides are kept on the mesh as they are."""
    for e in handles(obj):
        bpy.data.objects.remove(e)
    lattice = edit.get("lattice", {})
    size3 = lattice.get("size", 9)
    settings.lattice_size = size3 if isinstance(size3, list) else [size3] * 3
    settings.lattice_placement = lattice.get("placement", "uniform").upper()
    settings.lattice_padding = lattice.get("padding", 0.25)
    last = edit["edits"][-1]
    settings.solver = last.get("solver", "min-norm").upper().replace("-", "_")
    settings.preserve_volume = last.get("preserve_volume", False)
    kept = []
    for c in last["constraints"]:
        weight = c.get("weight")
        if "move" in c:
            add_handle(obj, "handle", c["move"], size, target=c["to"], weight=weight)[POINT_ONLY] = True
        elif "pin" in c:
            add_handle(obj, "pin", c["pin"], size, weight=weight)
        elif "frame" in c:
            e = add_handle(obj, "handle", c["frame"], size, target=c.get("to", c["frame"]), weight=weight)
            _turn(e, c.get("rotate"))
        elif "region" in c and "sphere" in c["region"]:
            # The Empty rests at the sphere's centre; its motion is the region's, whatever the pivot.
            centre, radius = c["region"]["sphere"]
            rotate = c.get("rotate")
            turn = Quaternion(Vector(rotate["axis"]).normalized(), math.radians(rotate["degrees"])) if rotate else Quaternion()
            pivot = Vector(rotate.get("pivot", centre)) if rotate else Vector(centre)
            moved = turn @ (Vector(centre) - pivot) + pivot + Vector(c.get("translate", (0, 0, 0)))
            e = add_handle(obj, "region", centre, radius, target=list(moved), weight=weight)
            _turn(e, rotate)
        else:  # control-point offsets, box regions, connects: kept as they are
            kept.append(c)
    obj[EXTRA] = json.dumps({"earlier": edit["edits"][:-1], "constraints": kept})
    return len(last["constraints"]) - len(kept), kept


# ---- the deform ------------------------------------------------------------------------------------------------------

def deform(obj, settings, resolution=None, depsgraph=None, preview=False, modifiers=True, progress=None):
    """Deform the mesh object by its handles: (V, F, report, attributes or None), local frame. `modifiers`: the mesh
    as its modifiers leave it (what the viewport shows), else its own mesh."""
    vw = module(settings.module_preference())
    V, F, attributes = source_arrays(obj, depsgraph, modifiers)
    edit = edit_of(obj, settings)
    size = {"voxel_size": settings.voxel_size} if settings.voxel_size > 0 and resolution is None else {"resolution": resolution or settings.resolution}
    result = vw.deform(V, F, edit, **size, mesher="features" if settings.mesher == "FEATURES" else "mc", snap=settings.snap and not preview,
                       attributes=attributes, progress=progress)
    return result if attributes is not None else (*result, None)


def options_of(settings, resolution=None):
    """The command-line options that give the same deform as `deform` with these settings."""
    size = f"--voxel-size {settings.voxel_size!r}" if settings.voxel_size > 0 and resolution is None else f"--resolution {resolution or settings.resolution}"
    return size + (" --mesher features" if settings.mesher == "FEATURES" else "") + ("" if settings.snap else " --no-snap")


def fill_mesh(me, V, F, attributes=None):
    """Replace the Blender mesh's geometry by voxwarp's arrays (smooth shaded but for edges over 30 degrees), with
    UV map, custom split normals, colour and material indices from `attributes`."""
    me.clear_geometry()
    n, m = len(V), len(F)
    me.vertices.add(n)
    me.vertices.foreach_set("co", np.ascontiguousarray(V, np.float32).ravel())
    me.loops.add(3 * m)
    me.loops.foreach_set("vertex_index", np.ascontiguousarray(F, np.int32).ravel())
    me.polygons.add(m)
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * m, 3, dtype=np.int32))
    me.polygons.foreach_set("loop_total", np.full(m, 3, np.int32))
    me.polygons.foreach_set("use_smooth", np.ones(m, bool))
    if hasattr(me, "use_auto_smooth"):  # edges sharper than 30 degrees (the feature mesher's) shaded sharp
        me.use_auto_smooth, me.auto_smooth_angle = True, math.radians(30)
    if attributes:
        if "uv_index" in attributes and len(attributes["uv"]):
            index = np.asarray(attributes["uv_index"]).ravel()
            uv = np.asarray(attributes["uv"], np.float32)[np.maximum(index, 0)]
            uv[index < 0] = 0
            layer = me.uv_layers.new(name="UVMap")
            layer.data.foreach_set("uv", uv.ravel())
        if "material" in attributes:
            me.polygons.foreach_set("material_index", np.maximum(np.asarray(attributes["material"], np.int32), 0))
        if "colour" in attributes:
            rgba = np.ones((n, 4), np.float32)
            rgba[:, :3] = attributes["colour"]
            layer = me.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
            field = "color_srgb" if hasattr(layer.data[0], "color_srgb") else "color"
            layer.data.foreach_set(field, rgba.ravel())
    me.update(calc_edges=True)
    if attributes and "normal_index" in attributes and len(attributes["normal"]):
        index = np.asarray(attributes["normal_index"]).ravel()
        normals = np.asarray(attributes["normal"], np.float32)[np.maximum(index, 0)]
        normals[index < 0] = 0  # a zero custom normal: Blender's own there
        if hasattr(me, "use_auto_smooth"):  # custom normals need it before Blender 4.1
            me.use_auto_smooth = True
        me.normals_split_custom_set(normals)


def result_object(obj, name):
    """A new mesh object beside `obj`, with its transform and its materials in the same slots."""
    me = bpy.data.meshes.new(name)
    for slot in obj.material_slots:
        me.materials.append(slot.material)
    out = bpy.data.objects.new(name, me)
    for c in obj.users_collection or [bpy.context.scene.collection]:
        c.objects.link(out)
    out.matrix_world = obj.matrix_world.copy()
    return out


def summary(report, seconds, triangles):
    """One line for the panel and the report area."""
    worst = max((c.get("residual_voxels", 0.0) for e in report.get("edits", []) for c in e.get("constraints", [])), default=0.0)
    return f"{triangles:,} triangles, voxel {report.get('voxel_size', 0):.4g}, worst constraint miss {worst:.2f} voxel, {seconds:.2f} s"


last_report = None  # the last Apply's deform report (the dict `voxwarp deform --report` writes)


def apply(obj, settings, in_place=False, progress=None):
    """Voxwarp Deform: the deformed mesh as a new object (its materials, UVs and colours with it), or in place of
    the mesh's own geometry (before its modifiers, which then act on the deformed mesh) with its handles' rest moved
    to where they are. Returns (object, summary line)."""
    start = time.perf_counter()
    global last_report
    V, F, report, attributes = deform(obj, settings, modifiers=not in_place, progress=progress)
    seconds = time.perf_counter() - start
    last_report = report
    if in_place:
        fill_mesh(obj.data, V, F, attributes)
        for e in handles(obj):
            set_rest(e)
        obj[EXTRA] = "{}"  # the earlier edits and control points are in the geometry now
        out = obj
    else:
        out = result_object(obj, f"{obj.name} voxwarp")
        fill_mesh(out.data, V, F, attributes)
    return out, summary(report, seconds, len(F))
