"""Checks of the voxwarp add-on inside Blender, run by python/tests/test_blender_addon.py:

    blender -b --factory-startup --python blender/tests/checks.py -- CHECK OUT.json [ARGS]

Each check drives the add-on through its operators as a user would, measures, and writes its figures to OUT.json
for the test to judge. The add-on is loaded from the source tree and the module from build/python (or
VOXWARP_PYTHONPATH). `undo` needs a window: it runs under xvfb-run without -b, from a timer.
"""

import json
import math
import os
import sys
import time
import traceback

import bpy
import numpy as np
from mathutils import Euler, Vector
from mathutils.bvhtree import BVHTree

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, os.environ.get("VOXWARP_PYTHONPATH", os.path.join(ROOT, "build", "python")))
import voxwarp  # noqa: E402
import voxwarp_blender  # noqa: E402
from voxwarp_blender import core, ui  # noqa: E402

DATA = os.environ.get("VOXWARP_DATA_DIR", os.path.join(ROOT, "data"))


def data(name):
    return os.path.join(DATA, name)


def empty_scene():
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)


def mesh_object(name, V, F):
    """A mesh object from voxwarp's arrays, active and selected, in object mode."""
    me = bpy.data.meshes.new(name)
    core.fill_mesh(me, V, F)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    select(obj)
    return obj


def select(obj):
    for o in bpy.context.selected_objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def add(obj, kind, at):
    """A handle through the add-on's operator, at the 3D cursor placed on `at` (world = the mesh's frame here)."""
    select(obj)
    bpy.context.scene.cursor.location = at
    assert bpy.ops.voxwarp.add_handle(kind=kind, at="CURSOR") == {"FINISHED"}
    return bpy.context.view_layer.objects.active


def arrays(obj, modifiers=True):
    """An object's (evaluated) mesh as (V, F) triangles, in its local frame."""
    if modifiers:
        return core.source_arrays(obj)[:2]
    me = obj.data
    me.calc_loop_triangles()
    V = np.array([v.co[:] for v in me.vertices])
    F = np.array([t.vertices[:] for t in me.loop_triangles], np.int32)
    return V, F


# ---- the analytic bend --------------------------------------------------------------------------------------------

RADIUS = 4 / (math.pi / 2)  # the 4 x 1 x 1 box's axis bent 90 degrees into a quarter circle about (-2, R, z)


def bend(P):
    """The exact bend: the box's left end face stays, its axis becomes the quarter circle (data/box_bend.json)."""
    phi = (P[:, 0] + 2) / RADIUS
    r = RADIUS - P[:, 1]
    return np.stack([-2 + r * np.sin(phi), RADIUS - r * np.cos(phi), P[:, 2]], axis=1)


def box_grid(n=(160, 40, 40)):
    """The 4 x 1 x 1 box's surface as a fine triangle grid (each face n cells a side)."""
    lo, hi = np.array([-2, -0.5, -0.5]), np.array([2, 0.5, 0.5])
    V, F = [], []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, 1):
            a, b = np.meshgrid(np.linspace(lo[u], hi[u], n[u] + 1), np.linspace(lo[v], hi[v], n[v] + 1), indexing="ij")
            P = np.zeros((a.size, 3))
            P[:, u], P[:, v], P[:, axis] = a.ravel(), b.ravel(), (hi if side else lo)[axis]
            i = np.arange(n[u])[:, None] * (n[v] + 1) + np.arange(n[v])[None, :]
            i = i.ravel() + sum(len(x) for x in V)
            F += [np.stack([i, i + n[v] + 1, i + n[v] + 2], 1), np.stack([i, i + n[v] + 2, i + 1], 1)]
            V.append(P)
    return np.concatenate(V), np.concatenate(F)


def samples(V, F, count, rng):
    """Points spread over a triangle mesh by area."""
    t = V[F]
    area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    pick = rng.choice(len(F), count, p=area / area.sum())
    a, b = rng.random(count), rng.random(count)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    t = t[pick]
    return t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])


def to_surface(points, V, F):
    tree = BVHTree.FromPolygons([tuple(v) for v in V], [tuple(int(i) for i in f) for f in F])
    return np.array([(Vector(p) - tree.find_nearest(Vector(p))[0]).length for p in points])


def symmetric(V, F, exact, count=20000, seed=1):
    """Distances between a mesh and the exact surface, both ways, over area samples: (mean, p99, max)."""
    rng = np.random.default_rng(seed)
    d = np.concatenate([to_surface(samples(V, F, count, rng), *exact), to_surface(samples(*exact, count, rng), V, F)])
    return float(d.mean()), float(np.percentile(d, 99)), float(d.max())


def check_bend(out, resolution=64):
    """The box bent 90 degrees by two handles placed with the add-on's operators (frames: the left end's left as it
    is, the right end's moved and turned), against the arc; and Blender's Simple Deform on the same box."""
    empty_scene()
    V, F = voxwarp.read_mesh(data("box.obj"))
    box = mesh_object("box", V, F)
    box.voxwarp.solver = "RIGID"
    box.voxwarp.resolution = resolution
    box.voxwarp.lattice_size = (9, 5, 5)  # cells about as wide as long across the bar (README, "Edit files")
    add(box, "HANDLE", (-2, 0, 0))  # left where it is: the end's frame held
    handle = add(box, "HANDLE", (2, 0, 0))
    handle.location = bend(np.array([[2.0, 0, 0]]))[0]
    handle.rotation_euler = Euler((0, 0, math.pi / 2))
    select(box)
    start = time.perf_counter()
    assert bpy.ops.voxwarp.deform() == {"FINISHED"}
    seconds = time.perf_counter() - start
    result = bpy.context.view_layer.objects.active
    report = core.last_report
    h = report["voxel_size"]
    exact = bend(box_grid()[0]), box_grid()[1]
    figures = {"voxel_size": h, "seconds": seconds, "handles": len(core.handles(box)), "result": result.name}
    mean, p99, worst = symmetric(*arrays(result), exact)
    figures["voxwarp"] = {"mean": mean / h, "p99": p99 / h, "max": worst / h, "triangles": len(result.data.polygons),
                          "volume_change_percent": report["volume_change_percent"]}
    # Blender's Simple Deform, bend 90 degrees about Z with its origin on the left end: the same analytic map at
    # each vertex, straight faces between (the coarse box), and with a Simple subdivision first (16 cuts an edge).
    origin = bpy.data.objects.new("bend origin", None)
    bpy.context.scene.collection.objects.link(origin)
    origin.location = (-2, 0, 0)
    for label, levels in (("simple_deform", 0), ("simple_deform_subdivided", 4)):
        o = mesh_object(label, V, F)
        if levels:
            sub = o.modifiers.new("subdivide", "SUBSURF")
            sub.subdivision_type, sub.levels = "SIMPLE", levels
        m = o.modifiers.new("bend", "SIMPLE_DEFORM")
        m.deform_method, m.deform_axis, m.angle, m.origin = "BEND", "Z", math.pi / 2, origin
        bpy.context.view_layer.update()
        W, G = arrays(o)
        mean, p99, worst = symmetric(W, G, exact)
        figures[label] = {"mean": mean / h, "p99": p99 / h, "max": worst / h, "triangles": len(G), "end": W[np.argmax(W[:, 1])].tolist()}
    return figures


def bunny_with_ear_handle(resolution=64):
    """The bunny with the bundled ear edit's handle and pins (data/bunny_ear.json) placed by the operators."""
    empty_scene()
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    bunny = mesh_object("bunny", V, F)
    bunny.voxwarp.resolution = resolution
    edit = json.load(open(data("bunny_ear.json")))["edits"][0]["constraints"]
    for c in edit:
        e = add(bunny, "HANDLE" if "move" in c else "PIN", c.get("move", c.get("pin")))
        if "to" in c:
            e.location = c["to"]
    select(bunny)
    return bunny


def check_files(out):
    """Edit files both ways: the bundled ear edit imported as handles and exported again; and a deform made here
    beside the edit file and mesh exported from Blender, for the test to run through `voxwarp deform`."""
    folder = os.path.dirname(out)
    figures = {}
    # Import, export: the same constraints, numbers and all.
    empty_scene()
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    bunny = mesh_object("bunny", V, F)
    assert bpy.ops.voxwarp.import_edit(filepath=data("bunny_ear.json")) == {"FINISHED"}
    figures["imported_handles"] = len(core.handles(bunny))
    exported = os.path.join(folder, "roundtrip.json")
    select(bunny)
    assert bpy.ops.voxwarp.export_edit(filepath=exported, with_mesh=False) == {"FINISHED"}
    figures["roundtrip"] = exported
    # Frames and a sphere region, imported and exported: the same entries (rotations through Blender's floats).
    for mesh, name in (("box.obj", "box_frames.json"), ("bunny.obj", "bunny_ear_turn.json")):
        empty_scene()
        obj = mesh_object(name, *voxwarp.read_mesh(data(mesh)))
        assert bpy.ops.voxwarp.import_edit(filepath=data(name)) == {"FINISHED"}
        select(obj)
        again = os.path.join(folder, "again_" + name)
        assert bpy.ops.voxwarp.export_edit(filepath=again, with_mesh=False) == {"FINISHED"}
        figures["again_" + name] = again
    # A handle moved and turned, a region held, a pin: exported with the mesh, and the deform made here.
    bunny = bunny_with_ear_handle()
    handle = next(e for e in core.handles(bunny) if e["voxwarp_kind"] == "handle")
    handle.rotation_euler = Euler((0.3, 0, 0.2))
    add(bunny, "REGION", (0.0, 1.0, 0.0))
    select(bunny)
    bunny.voxwarp.mesher = "FEATURES"
    edit = os.path.join(folder, "from_blender.json")
    assert bpy.ops.voxwarp.export_edit(filepath=edit, with_mesh=True) == {"FINISHED"}
    V2, F2, report, _ = core.deform(bunny, bunny.voxwarp)
    voxwarp.write_mesh(os.path.join(folder, "blender_out.obj"), V2, F2)
    figures.update(edit=edit, mesh=os.path.join(folder, "from_blender.obj"), output=os.path.join(folder, "blender_out.obj"),
                   options=core.options_of(bunny.voxwarp).split())
    return figures


def check_attributes(out):
    """Spot, imported by Blender's own OBJ importer (UV map, material, texture), given a colour that is a linear
    function of position, with the bundled head-turn edit imported as handles and then reset (nothing moves):
    Apply's new object carries the material, the UV map and the colour, each as the source has it there."""
    empty_scene()
    bpy.ops.wm.obj_import(filepath=data("spot_triangulated.obj"))
    spot = bpy.context.selected_objects[0]
    select(spot)
    spot.voxwarp.resolution = 64
    V, F = arrays(spot, modifiers=False)
    lo, hi = V.min(axis=0), V.max(axis=0)
    layer = spot.data.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
    rgba = np.ones((len(V), 4), np.float32)
    rgba[:, :3] = (V - lo) / (hi - lo)
    field = "color_srgb" if hasattr(layer.data[0], "color_srgb") else "color"
    layer.data.foreach_set(field, rgba.ravel())
    spot.data.color_attributes.active_color = layer
    assert bpy.ops.voxwarp.import_edit(filepath=data("spot_head.json")) == {"FINISHED"}
    select(spot)
    assert bpy.ops.voxwarp.reset_handles() == {"FINISHED"}
    assert bpy.ops.voxwarp.deform() == {"FINISHED"}
    result = bpy.context.view_layer.objects.active
    me = result.data
    figures = {"source_materials": [s.material.name for s in spot.material_slots], "materials": [s.material.name if s.material else None for s in result.material_slots],
               "uv_layers": len(me.uv_layers), "colour_layers": len(me.color_attributes), "triangles": len(me.polygons)}
    # Each output corner's texture coordinate against the source's, interpolated at the nearest source point.
    source = spot.data
    source.calc_loop_triangles()
    tree = BVHTree.FromPolygons([v.co[:] for v in source.vertices], [t.vertices[:] for t in source.loop_triangles])
    source_uv = source.uv_layers.active.data
    from mathutils.interpolate import poly_3d_calc
    texels, colour = [], []
    out_colour = me.color_attributes["Col"].data
    for poly in list(me.polygons)[::7]:
        for loop in poly.loop_indices:
            v = me.loops[loop].vertex_index
            p = me.vertices[v].co
            q, _, t, _ = tree.find_nearest(p)
            tri = source.loop_triangles[t]
            w = poly_3d_calc([source.vertices[i].co for i in tri.vertices], q)
            uv = sum((Vector(source_uv[l].uv) * wi for l, wi in zip(tri.loops, w)), Vector((0, 0)))
            texels.append((Vector(me.uv_layers[0].data[loop].uv) - uv).length * 1024)
            colour.append(np.abs(np.array(getattr(out_colour[v], field)[:3]) - (np.array(p) - lo) / (hi - lo)).max())
    figures["uv_texels"] = {"median": float(np.median(texels)), "p90": float(np.percentile(texels, 90)), "corners": len(texels)}
    figures["colour"] = {"median": float(np.median(colour)), "p99": float(np.percentile(colour, 99))}
    return figures


def check_normals(out):
    """A cube with custom split normals that its geometry does not give (each corner's normal points from the centre
    to its vertex: a rounded look on flat sides, common in games), a pin at its centre (nothing moves): Apply's object
    has custom normals, each loop's the source's interpolated at the nearest source point."""
    empty_scene()
    bpy.ops.mesh.primitive_cube_add(size=2)
    cube = bpy.context.active_object
    me = cube.data
    if hasattr(me, "use_auto_smooth"):
        me.use_auto_smooth = True
    me.normals_split_custom_set([me.vertices[l.vertex_index].co.normalized()[:] for l in me.loops])
    cube.voxwarp.resolution = 32
    add(cube, "PIN", (0, 0, 0))
    select(cube)
    assert bpy.ops.voxwarp.deform() == {"FINISHED"}
    result = bpy.context.view_layer.objects.active
    out_me = result.data
    figures = {"source_custom": me.has_custom_normals, "custom": out_me.has_custom_normals, "triangles": len(out_me.polygons)}
    me.calc_loop_triangles()
    me.calc_normals_split()
    out_me.calc_normals_split()
    tree = BVHTree.FromPolygons([v.co[:] for v in me.vertices], [t.vertices[:] for t in me.loop_triangles])
    from mathutils.interpolate import poly_3d_calc
    degrees = []
    for poly in list(out_me.polygons)[::3]:
        for loop in poly.loop_indices:
            p = out_me.vertices[out_me.loops[loop].vertex_index].co
            q, _, t, _ = tree.find_nearest(p)
            tri = me.loop_triangles[t]
            w = poly_3d_calc([me.vertices[i].co for i in tri.vertices], q)
            n = sum((Vector(me.loops[l].normal) * wi for l, wi in zip(tri.loops, w)), Vector((0, 0, 0))).normalized()
            degrees.append(math.degrees(Vector(out_me.loops[loop].normal).angle(n, 0.0)))
    figures["degrees"] = {"median": float(np.median(degrees)), "p99": float(np.percentile(degrees, 99)), "max": float(np.max(degrees)), "loops": len(degrees)}
    return figures


def check_handles(out):
    """Handles as the operators place them: at the selected vertices in Edit Mode, at the 3D cursor of a moved and
    scaled mesh (its own frame), and a handle shown as a sphere working as a region."""
    empty_scene()
    V, F = voxwarp.read_mesh(data("box.obj"))
    box = mesh_object("box", V, F)
    box.location, box.scale = (10, 0, 0), (2, 2, 2)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="DESELECT")
    bpy.ops.object.mode_set(mode="OBJECT")
    for i in (1, 2):  # vertices (2, -0.5, -0.5) and (2, 0.5, -0.5)
        box.data.vertices[i].select = True
    bpy.ops.object.mode_set(mode="EDIT")
    assert bpy.ops.voxwarp.add_handle(kind="HANDLE") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    at_vertices = core.handles(box)[0]
    select(box)
    bpy.context.scene.cursor.location = (6, 0, 0)  # world: the box's local (-2, 0, 0)
    assert bpy.ops.voxwarp.add_handle(kind="PIN") == {"FINISHED"}
    pin = next(e for e in core.handles(box) if e["voxwarp_kind"] == "pin")
    at_vertices.empty_display_type = "SPHERE"
    at_vertices.empty_display_size = 0.1
    constraints = core.constraints_of(box)
    return {"at_vertices": core.rest_of(at_vertices)[0], "pin": core.rest_of(pin)[0], "kinds": [core.kind_of(e) for e in core.handles(box)],
            "constraints": constraints, "parent": at_vertices.parent.name, "collection": [c.name for c in at_vertices.users_collection]}


class Layout:
    """Stands in for the sidebar's UILayout while the panel's draw() runs (a panel draws only in its open tab of
    a window): records each label, and checks that each property and operator it names exists."""

    def __init__(self, log):
        self.log = log

    def _child(self, *args, **kwargs):
        return Layout(self.log)

    row = column = box = _child

    def label(self, text="", icon="NONE"):
        self.log.append(("label", text))

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"panel: {type(data).__name__} has no property {name}"
        self.log.append(("prop", name))

    def operator(self, idname, **kwargs):
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name) and getattr(getattr(bpy.ops, category), name).poll() in (True, False), idname
        self.log.append(("operator", idname))
        return type("Properties", (), {})()


def check_panel(out):
    """The sidebar panel's contents with a bunny and its handles active, and with nothing."""
    bunny = bunny_with_ear_handle()
    bunny.voxwarp.status = "a status line"
    figures = {}
    for label, active in (("bunny", bunny), ("handle", core.handles(bunny)[0]), ("nothing", None)):
        bpy.context.view_layer.objects.active = active
        log = []
        ui.VOXWARP_PT_panel.draw(type("Panel", (), {"layout": Layout(log)})(), bpy.context)
        figures[label] = log
    return figures


def check_errors(out):
    """Bad input reported by the operators, Blender carrying on: an empty mesh, a mesh without handles, a handle put
    far outside the model, a malformed edit file; and an open scan (not manifold) deformed."""
    figures = {}

    def attempt(label, call):
        try:
            result = call()
            figures[label] = {"result": sorted(result)}
        except RuntimeError as e:  # an operator's ERROR report, as Python sees it
            figures[label] = {"error": str(e)}

    empty_scene()
    empty = mesh_object("empty", np.zeros((0, 3)), np.zeros((0, 3), np.int32))
    attempt("empty_mesh", lambda: bpy.ops.voxwarp.deform())
    V, F = voxwarp.read_mesh(data("box.obj"))
    box = mesh_object("box", V, F)
    attempt("no_handles", lambda: bpy.ops.voxwarp.deform())
    add(box, "HANDLE", (40, 0, 0))  # ten model lengths off to the side
    add(box, "PIN", (-2, 0, 0))
    select(box)
    attempt("handle_outside", lambda: bpy.ops.voxwarp.deform())
    bad = os.path.join(os.path.dirname(out), "bad_edit.json")
    with open(bad, "w") as f:
        f.write('{"edits": [{"constraints": [{"move": [0, 0], "to": [1, 2, 3]}]}]}')
    attempt("malformed_edit", lambda: bpy.ops.voxwarp.import_edit(filepath=bad))
    figures["handles_after_malformed"] = len(core.handles(box))
    V, F = voxwarp.read_mesh(data("snowden_lo.obj"))
    scan = mesh_object("scan", V, F)
    scan.voxwarp.resolution = 64
    lo, hi = V.min(axis=0), V.max(axis=0)
    add(scan, "PIN", (lo + hi) / 2 - [0, (hi - lo)[1] * 0.3, 0])
    top = V[np.argmax(V[:, 1])]
    e = add(scan, "HANDLE", top)
    e.location = top + [0, (hi - lo)[1] * 0.05, 0]
    select(scan)
    attempt("open_scan", lambda: bpy.ops.voxwarp.deform())
    figures["objects"] = sorted(o.name for o in bpy.data.objects if o.type == "MESH")
    return figures


def check_live(out, moves=12):
    """Live mode on the bunny: each handle move (a depsgraph update) re-runs the deform at the preview resolution
    into the live object, and once the handles rest the timer makes it at full resolution, as Apply would."""
    bunny = bunny_with_ear_handle(resolution=96)
    bunny.voxwarp.preview_resolution = 64
    handle = next(e for e in core.handles(bunny) if e["voxwarp_kind"] == "handle")
    bunny.voxwarp.live = True
    live = bunny.voxwarp.preview
    figures = {"live_object": live.name if live else None, "updates": []}
    start_tip = Vector(handle.location)
    seconds = []
    for i in range(moves):
        handle.location = start_tip + Vector((0, 0.05 * (i + 1), 0))
        t = time.perf_counter()
        bpy.context.view_layer.update()
        seconds.append(time.perf_counter() - t)
        V, _ = arrays(live, modifiers=False)
        figures["updates"].append({"top": float(V[:, 1].max()), "vertices": len(V), "status": bunny.voxwarp.status})
    figures["seconds"] = seconds
    time.sleep(ui.SETTLE + 0.05)
    ui.finish_live()
    V, F = arrays(live, modifiers=False)
    figures["full"] = {"vertices": len(V), "status": bunny.voxwarp.status}
    V2, F2, _, _ = core.deform(bunny, bunny.voxwarp)
    figures["full_matches_apply"] = bool(len(V) == len(V2) and np.abs(V - V2).max() < 1e-5)
    bunny.voxwarp.live = False
    figures["live_object_after_off"] = sum(1 for o in bpy.data.objects if o.name.endswith("voxwarp live"))
    return figures


def check_undo(out):
    """(In a window, one step per timer tick, as a user's clicks come.) The bunny, imported by Blender's own OBJ
    importer, its ear pulled by a handle placed with the operator and applied in place, then Undo: the original
    mesh and the handle's rest; and Apply as a new object, then Undo: the object gone. Operators are called with
    undo=True, as a click in the UI calls them (from a script Blender pushes no undo step otherwise)."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    figures, state = {}, {}

    def world(p):  # a point of the file in Blender's world (the importer turns Y-up files to Z-up)
        obj = state["bunny"]
        return obj.matrix_world @ Vector(state["to_local"](np.asarray(p, float)))

    def steps():
        bpy.ops.object.select_all(action="SELECT")
        bpy.ops.object.delete("EXEC_DEFAULT", True)
        bpy.ops.wm.obj_import("EXEC_DEFAULT", True, filepath=data("bunny.obj"))
        yield
        bunny = state["bunny"] = bpy.context.selected_objects[0]
        bunny.name = "bunny"
        V = arrays(bunny, modifiers=False)[0]
        file_V, _ = voxwarp.read_mesh(data("bunny.obj"))
        baked = file_V[:, [0, 2, 1]] * [1, -1, 1]
        state["to_local"] = (lambda p: p) if np.allclose(V, file_V, atol=1e-5) else (lambda p: p[..., [0, 2, 1]] * [1, -1, 1])
        assert np.allclose(V, state["to_local"](file_V), atol=1e-5) or np.allclose(V, baked, atol=1e-5)
        bunny.voxwarp.resolution = 64
        for c in json.load(open(data("bunny_ear.json")))["edits"][0]["constraints"]:
            select(bunny)
            bpy.context.scene.cursor.location = world(c.get("move", c.get("pin")))
            bpy.ops.voxwarp.add_handle("EXEC_DEFAULT", True, kind="HANDLE" if "move" in c else "PIN", at="CURSOR")
            if "to" in c:
                bpy.context.view_layer.objects.active.location = state["to_local"](np.asarray(c["to"], float))
                bpy.ops.ed.undo_push(message="handle moved")
            yield
        select(bunny)
        state["before"] = arrays(bunny, modifiers=False)[0]
        figures["rest_before"] = core.rest_of(next(e for e in core.handles(bunny) if e["voxwarp_kind"] == "handle"))[0]
        assert bpy.ops.voxwarp.deform("EXEC_DEFAULT", True, in_place=True) == {"FINISHED"}
        yield
        after = arrays(bpy.data.objects["bunny"], modifiers=False)[0]
        before = state["before"]
        up = state["to_local"](np.array([0.0, 1.0, 0.0]))  # the file's up in the mesh's frame
        figures["in_place"] = {"before": len(before), "after": len(after), "top_before": float((before @ up).max()), "top_after": float((after @ up).max())}
        bpy.ops.ed.undo()
        yield
        bunny = bpy.data.objects["bunny"]
        undone = arrays(bunny, modifiers=False)[0]
        figures["undone"] = {"vertices": len(undone), "max_difference": float(np.abs(undone - before).max()) if len(undone) == len(before) else None,
                             "rest_of_handle": core.rest_of(next(e for e in core.handles(bunny) if e["voxwarp_kind"] == "handle"))[0]}
        select(bunny)
        state["names"] = {o.name for o in bpy.data.objects}
        assert bpy.ops.voxwarp.deform("EXEC_DEFAULT", True) == {"FINISHED"}
        yield
        figures["new_objects"] = sorted({o.name for o in bpy.data.objects} - state["names"])
        bpy.ops.ed.undo()
        yield
        figures["after_undo"] = sorted({o.name for o in bpy.data.objects} - state["names"])

    for _ in steps():
        yield
    state["figures"] = figures
    yield figures


CHECKS = {"attributes": check_attributes, "normals": check_normals, "bend": check_bend, "handles": check_handles, "panel": check_panel, "files": check_files, "errors": check_errors, "live": check_live, "undo": check_undo}


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    check, out = argv[0], argv[1]
    voxwarp_blender.register()
    try:
        figures = CHECKS[check](out)
        code = 0
    except Exception:  # noqa: BLE001
        figures = {"exception": traceback.format_exc()}
        code = 1
    with open(out, "w") as f:
        json.dump(figures, f, indent=2)
    print(json.dumps(figures, indent=2)[:4000], flush=True)
    return code


if __name__ == "__main__" and bpy.app.background:
    sys.exit(main())
elif __name__ == "__main__":  # in a window (undo): a check is a generator, one step per timer tick; its last yield is its figures
    _steps = None

    def _tick():
        global _steps
        argv = sys.argv[sys.argv.index("--") + 1:]
        window = bpy.context.window_manager.windows[0]
        area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
        try:
            with bpy.context.temp_override(window=window, area=area):
                if _steps is None:
                    voxwarp_blender.register()
                    _steps = CHECKS[argv[0]](argv[1])
                figures = next(_steps)
        except Exception:  # noqa: BLE001
            figures = {"exception": traceback.format_exc()}
        if figures is None:
            return 0.2
        with open(argv[1], "w") as f:
            json.dump(figures, f, indent=2)
        print(json.dumps(figures, indent=2)[:4000], flush=True)
        os._exit(1 if "exception" in figures else 0)

    bpy.app.timers.register(_tick, first_interval=0.5)
