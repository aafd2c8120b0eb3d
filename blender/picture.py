"""The README's Blender picture, rendered by Blender itself (Workbench, headless): the 12-triangle 4 x 1 x 1 box
bent 90 degrees by Blender's Simple Deform (left) and by two voxwarp handles through the add-on (right).

    blender -b --factory-startup --python blender/picture.py -- docs/pictures/blender_bend.png
"""

import math
import os
import sys

import bpy
import numpy as np
from mathutils import Euler, Vector

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests"))
import checks  # noqa: E402
from checks import voxwarp, voxwarp_blender  # noqa: E402

out = os.path.abspath(sys.argv[sys.argv.index("--") + 1])
voxwarp_blender.register()
checks.empty_scene()
V, F = voxwarp.read_mesh(checks.data("box.obj"))

# Blender's Simple Deform: bend 90 degrees about Z, its origin on the box's left end.
simple = checks.mesh_object("Simple Deform", V, F)
for p in simple.data.polygons:
    p.use_smooth = False
origin = bpy.data.objects.new("origin", None)
bpy.context.scene.collection.objects.link(origin)
origin.location = (-2, 0, 0)
m = simple.modifiers.new("bend", "SIMPLE_DEFORM")
m.deform_method, m.deform_axis, m.angle, m.origin = "BEND", "Z", math.pi / 2, origin

# voxwarp: a handle on each end (frames), the left one left as it is, the right one moved and turned 90 degrees.
box = checks.mesh_object("box", V, F)
box.voxwarp.solver = "RIGID"
box.voxwarp.resolution = 96
box.voxwarp.lattice_size = (9, 5, 5)
box.voxwarp.mesher = "FEATURES"  # the box keeps its edges
checks.add(box, "HANDLE", (-2, 0, 0))
handle = checks.add(box, "HANDLE", (2, 0, 0))
handle.location = checks.bend(np.array([[2.0, 0, 0]]))[0]
handle.rotation_euler = Euler((0, 0, math.pi / 2))
checks.select(box)
assert bpy.ops.voxwarp.deform() == {"FINISHED"}
result = bpy.context.view_layer.objects.active
box.hide_render = True
result.location.x += 5  # beside Simple Deform's

for text, x in (("Blender Simple Deform", -0.8), ("voxwarp, two handles", 4.2)):
    curve = bpy.data.curves.new(text, "FONT")
    curve.body, curve.align_x, curve.size = text, "CENTER", 0.38
    label = bpy.data.objects.new(text, curve)
    bpy.context.scene.collection.objects.link(label)
    label.location = (x, -1.5, 0)

scene = bpy.context.scene
scene.render.engine = "BLENDER_WORKBENCH"
scene.display.shading.light = "STUDIO"
scene.display.shading.color_type = "SINGLE"
scene.display.shading.single_color = (0.8, 0.62, 0.45)
scene.display.shading.show_cavity = True
scene.display.shading.show_object_outline = True
scene.display.shading.show_specular_highlight = True
scene.render.resolution_x, scene.render.resolution_y = 1200, 560
scene.render.film_transparent = False
scene.world = scene.world or bpy.data.worlds.new("World")
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
camera.data.type, camera.data.ortho_scale = "ORTHO", 11.5
camera.location = (1.7, -4.2, 9.0)
camera.rotation_euler = Euler((math.radians(30), 0, 0))
scene.camera = camera
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
print(f"wrote {out}")
