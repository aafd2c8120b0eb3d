"""The add-on's face in Blender: settings on each mesh object, the operators, the sidebar panel and Live mode.

Every operator reports voxwarp's own message in Blender's report area and returns CANCELLED on bad input (an
empty mesh, a handle far outside the model, a malformed edit file); none lets an exception through.
"""

import json
import os
import time

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, IntVectorProperty, PointerProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper
from mathutils import Vector

from . import core

SETTLE = 0.4  # seconds without a handle moving before Live computes at full resolution


def addon_preferences():
    addon = bpy.context.preferences.addons.get(__package__)
    return addon.preferences if addon is not None else None


def _live_changed(settings, context):
    obj = settings.id_data
    if settings.live:
        obj.display_type = "WIRE"
        _state.pop(obj.name, None)
        on_depsgraph_update(context.scene, context.evaluated_depsgraph_get())
    else:
        obj.display_type = "TEXTURED"
        _state.pop(obj.name, None)
        if settings.preview is not None:
            bpy.data.objects.remove(settings.preview)


class VoxwarpSettings(bpy.types.PropertyGroup):
    resolution: IntProperty(name="Resolution", description="Voxels along the model's longest side (--resolution)", default=128, min=8, max=1024)
    voxel_size: FloatProperty(name="Voxel size", description="Voxel size in the mesh's units; 0: from the resolution (--voxel-size)", default=0.0, min=0.0,
                              precision=4)
    preview_resolution: IntProperty(name="Preview resolution", description="Live mode's resolution while handles move", default=64, min=8, max=512)
    solver: EnumProperty(name="Solver", items=[("RIGID", "Rigid", "As rigid as possible where the material is: bends stay bends"),
                                               ("MIN_NORM", "Min-norm", "The least control-point motion (the papers')")], default="RIGID")
    preserve_volume: BoolProperty(name="Preserve volume", description="Keep the material's volume", default=False)
    mesher: EnumProperty(name="Mesher", items=[("MC", "Smooth", "Marching cubes (--mesher mc)"),
                                               ("FEATURES", "Sharp features", "Sharp edges and corners put back (--mesher features)")], default="MC")
    snap: BoolProperty(name="Snap", description="Output vertices onto the exact image of the input surface (off: --no-snap)", default=True)
    lattice_size: IntVectorProperty(name="Lattice", description="Control points per axis", size=3, default=(9, 9, 9), min=4, max=64)
    lattice_placement: EnumProperty(name="Placement", items=[("UNIFORM", "Uniform", "Evenly spaced, padded around the model"),
                                                             ("CLAMPED", "Clamped", "End points tripled, the image is the data box")], default="UNIFORM")
    lattice_padding: FloatProperty(name="Padding", description="How far the lattice reaches beyond the model, per side", default=0.25, min=0.0, max=4.0)
    live: BoolProperty(name="Live", description="The result follows the handles (preview resolution while they move)", default=False, update=_live_changed)
    preview: PointerProperty(type=bpy.types.Object, name="Preview")
    status: StringProperty(name="Status", default="")

    def module_preference(self):
        p = addon_preferences()
        return p.module_path if p is not None else ""


def _message(e):
    return str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__


def _make_active(context, obj):
    """The object alone selected, and active: what a user moves or looks at next."""
    for o in context.selected_objects:
        o.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj


class _OnMesh:
    @classmethod
    def poll(cls, context):
        return core.source_of(context.active_object) is not None


class VOXWARP_OT_add_handle(_OnMesh, bpy.types.Operator):
    """Add a voxwarp handle to the mesh, at the selected vertices (Edit Mode) or at the 3D cursor"""
    bl_idname = "voxwarp.add_handle"
    bl_label = "Add Voxwarp Handle"
    bl_options = {"REGISTER", "UNDO"}

    kind: EnumProperty(name="Kind", items=[("HANDLE", "Handle", "Move it (and turn it) to move the surface there"),
                                           ("PIN", "Pin", "Holds the surface where it is"),
                                           ("REGION", "Region", "A sphere: the surface inside follows its motion, or stays")])
    at: EnumProperty(name="At", items=[("AUTO", "Auto", "The selected vertices in Edit Mode, else the 3D cursor"),
                                       ("CURSOR", "3D cursor", ""), ("VERTEX", "Selected vertices", "")])

    def execute(self, context):
        obj = core.source_of(context.active_object)
        try:
            if self.at == "VERTEX" or (self.at == "AUTO" and obj.mode == "EDIT"):
                obj.update_from_editmode()
                selected = [v.co.copy() for v in obj.data.vertices if v.select]
                if not selected:
                    raise ValueError(f"{obj.name}: no vertex is selected")
                point = sum(selected, Vector()) / len(selected)
            else:
                point = obj.matrix_world.inverted_safe() @ context.scene.cursor.location
            e = core.add_handle(obj, self.kind.lower(), point, core.handle_size(obj, 0.15 if self.kind == "REGION" else 0.05))
        except Exception as e:  # noqa: BLE001 (reported, never raised into Blender)
            self.report({"ERROR"}, _message(e))
            return {"CANCELLED"}
        if obj.mode == "OBJECT":
            _make_active(context, e)
        self.report({"INFO"}, f"{e.name} at ({point.x:.4g}, {point.y:.4g}, {point.z:.4g})")
        return {"FINISHED"}


class VOXWARP_OT_deform(_OnMesh, bpy.types.Operator):
    """Deform the mesh by its handles: voxelize, warp, re-polygonize. The result is a new object (with the
    mesh's materials, UV map and colours), or replaces the mesh's own geometry"""
    bl_idname = "voxwarp.deform"
    bl_label = "Voxwarp Deform"
    bl_options = {"REGISTER", "UNDO"}

    in_place: BoolProperty(name="In place", description="Replace the mesh's geometry (the handles then rest where they are)", default=False,
                           options={"SKIP_SAVE"})  # never remembered from the last call: Apply makes a new object unless asked

    def execute(self, context):
        obj = core.source_of(context.active_object)
        if obj.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        wm = context.window_manager
        wm.progress_begin(0, 1)

        def progress(stage, fraction):  # the cursor's progress figure, as voxwarp's stages go
            wm.progress_update(fraction)
            return True

        try:
            out, line = core.apply(obj, obj.voxwarp, in_place=self.in_place, progress=progress)
        except Exception as e:  # noqa: BLE001 (voxwarp's errors, bad input: reported, never raised into Blender)
            obj.voxwarp.status = _message(e)
            self.report({"ERROR"}, _message(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        obj.voxwarp.status = line
        if not self.in_place:
            _make_active(context, out)
        self.report({"INFO"}, f"{out.name}: {line}")
        return {"FINISHED"}


class VOXWARP_OT_reset_handles(_OnMesh, bpy.types.Operator):
    """Put the mesh's handles back where they rest (no deformation)"""
    bl_idname = "voxwarp.reset_handles"
    bl_label = "Reset Handles"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        for e in core.handles(core.source_of(context.active_object)):
            location, rotation = core.rest_of(e)
            e.location = location
            e[core.TO] = location
            e.rotation_mode = "QUATERNION"
            e.rotation_quaternion = rotation
            e.rotation_mode = "XYZ"
        return {"FINISHED"}


class VOXWARP_OT_export_edit(_OnMesh, ExportHelper, bpy.types.Operator):
    """Write the mesh's handles as a voxwarp edit file (the mesh's own coordinates), and the mesh beside it"""
    bl_idname = "voxwarp.export_edit"
    bl_label = "Export Edit File"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    with_mesh: BoolProperty(name="With the mesh", description="Write the mesh beside it (NAME.obj, same frame), for `voxwarp deform`", default=True)

    def execute(self, context):
        obj = core.source_of(context.active_object)
        try:
            V, F, attributes = core.source_arrays(obj)
            text = core.edit_text(core.edit_of(obj, obj.voxwarp))
            partial = self.filepath + ".part"
            with open(partial, "w") as f:
                f.write(text)
            os.replace(partial, self.filepath)
            mesh = os.path.splitext(self.filepath)[0] + ".obj"
            if self.with_mesh:
                core.module(obj.voxwarp.module_preference()).write_mesh(mesh, V, F, attributes)
        except Exception as e:  # noqa: BLE001
            self.report({"ERROR"}, _message(e))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{self.filepath}: the same deform: voxwarp deform {os.path.basename(mesh)} {os.path.basename(self.filepath)} -o OUT "
                              + core.options_of(obj.voxwarp))
        return {"FINISHED"}


class VOXWARP_OT_import_edit(_OnMesh, ImportHelper, bpy.types.Operator):
    """Read a voxwarp edit file as handles on the mesh (its points in the mesh's own coordinates)"""
    bl_idname = "voxwarp.import_edit"
    bl_label = "Import Edit File"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})

    def execute(self, context):
        obj = core.source_of(context.active_object)
        try:
            core.module(obj.voxwarp.module_preference()).read_edit(self.filepath)  # the file's own message if it is wrong
            with open(self.filepath) as f:
                edit = json.load(f)
            made, kept = core.import_edit(obj, edit, obj.voxwarp, core.handle_size(obj, 0.05))
        except Exception as e:  # noqa: BLE001
            self.report({"ERROR"}, _message(e))
            return {"CANCELLED"}
        earlier = len(edit["edits"]) - 1
        self.report({"INFO"}, f"{os.path.basename(self.filepath)}: {made} handles" + (f", {len(kept)} control-point offsets kept" if kept else "")
                    + (f", {earlier} earlier edits kept" if earlier else ""))
        return {"FINISHED"}


class VOXWARP_PT_panel(bpy.types.Panel):
    bl_label = "Voxwarp"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Voxwarp"

    def draw(self, context):
        layout = self.layout
        obj = core.source_of(context.active_object)
        if obj is None:
            layout.label(text="Select a mesh (or one of its handles)")
            return
        s = obj.voxwarp
        try:
            core.module(s.module_preference())
        except RuntimeError as e:
            layout.label(text="voxwarp's module was not found", icon="ERROR")
            layout.label(text=_message(e)[:80])
            return
        col = layout.column(align=True)
        col.label(text=f"{obj.name}: {len(core.handles(obj))} handles")
        row = col.row(align=True)
        row.operator("voxwarp.add_handle", text="Handle").kind = "HANDLE"
        row.operator("voxwarp.add_handle", text="Pin").kind = "PIN"
        row.operator("voxwarp.add_handle", text="Region").kind = "REGION"
        col.operator("voxwarp.reset_handles")
        col = layout.column()
        col.prop(s, "resolution")
        col.prop(s, "voxel_size")
        col.prop(s, "solver")
        col.prop(s, "preserve_volume")
        col.prop(s, "mesher")
        col.prop(s, "snap")
        box = layout.box()
        box.prop(s, "lattice_size")
        box.prop(s, "lattice_placement")
        box.prop(s, "lattice_padding")
        row = layout.row()
        row.prop(s, "live")
        row.prop(s, "preview_resolution", text="Preview")
        layout.operator("voxwarp.deform", text="Apply (new object)").in_place = False
        layout.operator("voxwarp.deform", text="Apply in place").in_place = True
        row = layout.row(align=True)
        row.operator("voxwarp.import_edit", text="Import edit")
        row.operator("voxwarp.export_edit", text="Export edit")
        if s.status:
            layout.label(text=s.status)


class VoxwarpPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__
    module_path: StringProperty(name="Module folder", description="Folder holding voxwarp's Python package (voxwarp's build/python), if not shipped",
                                subtype="DIR_PATH", default="")

    def draw(self, context):
        self.layout.prop(self, "module_path")


# ---- Live mode -------------------------------------------------------------------------------------------------------

_state = {}  # mesh object name -> {"signature", "at", "full"}
_busy = False


def signature(obj):
    """What a live result depends on, besides the mesh: its handles' placements and the settings."""
    s = obj.voxwarp
    settings = (s.resolution, s.voxel_size, s.preview_resolution, s.solver, s.preserve_volume, s.mesher, s.snap, tuple(s.lattice_size),
                s.lattice_placement, s.lattice_padding)
    return settings + tuple((e.name, e.get(core.KIND), e.empty_display_size, e.get(core.WEIGHT), tuple(tuple(r) for r in e.matrix_world))
                            for e in core.handles(obj))


def live_update(obj, full, depsgraph=None):
    """The live result, at the preview resolution (full=False) or as Apply would make it (full=True)."""
    s = obj.voxwarp
    start = time.perf_counter()
    V, F, report, attributes = core.deform(obj, s, resolution=None if full else s.preview_resolution, depsgraph=depsgraph, preview=not full)
    out = s.preview
    if out is None or out.name not in bpy.data.objects:
        out = core.result_object(obj, f"{obj.name} voxwarp live")
        s.preview = out
    core.fill_mesh(out.data, V, F, attributes)
    out.matrix_world = obj.matrix_world.copy()
    s.status = ("" if full else "preview: ") + core.summary(report, time.perf_counter() - start, len(F))


def _run_live(obj, full, depsgraph=None):
    global _busy
    _busy = True
    try:
        live_update(obj, full, depsgraph)
    except Exception as e:  # noqa: BLE001 (shown in the panel; a handler must never raise)
        obj.voxwarp.status = _message(e)
        print(f"voxwarp live: {obj.name}: {_message(e)}")
    finally:
        _busy = False


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _busy:
        return
    for obj in scene.objects:
        if obj.type != "MESH" or not obj.voxwarp.live:
            continue
        sig = signature(obj)
        state = _state.get(obj.name)
        if state is not None and state["signature"] == sig:
            continue
        _run_live(obj, False, depsgraph)
        _state[obj.name] = {"signature": sig, "at": time.monotonic(), "full": False}
        if not bpy.app.timers.is_registered(finish_live):
            bpy.app.timers.register(finish_live, first_interval=SETTLE)


def finish_live():
    """Timer: each live result whose handles have rested SETTLE seconds, at full resolution. Returns when to look
    again (None: nothing left)."""
    pending = False
    for name, state in list(_state.items()):
        obj = bpy.data.objects.get(name)
        if obj is None or not obj.voxwarp.live:
            _state.pop(name, None)
            continue
        if state["full"]:
            continue
        if signature(obj) != state["signature"] or time.monotonic() - state["at"] < SETTLE:
            pending = True
            continue
        _run_live(obj, True)
        state["full"] = True
    return SETTLE if pending else None


classes = (VoxwarpSettings, VOXWARP_OT_add_handle, VOXWARP_OT_deform, VOXWARP_OT_reset_handles, VOXWARP_OT_export_edit, VOXWARP_OT_import_edit,
           VOXWARP_PT_panel, VoxwarpPreferences)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Object.voxwarp = PointerProperty(type=VoxwarpSettings)
    bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)


def unregister():
    if on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(on_depsgraph_update)
    if bpy.app.timers.is_registered(finish_live):
        bpy.app.timers.unregister(finish_live)
    del bpy.types.Object.voxwarp
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
