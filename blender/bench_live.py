"""Live mode's update rate inside Blender (the issue's goal: >= 5 updates a second on the bunny at a preview
resolution of 64), against voxwarp.deform alone in the same run:

    blender -b --factory-startup --python blender/bench_live.py [-- REPEATS]

Each update is what a handle's move costs in Blender: the depsgraph handler reads the mesh, turns the handles into
an edit, deforms at the preview resolution (no snap) and refills the live object's mesh. Medians of REPEATS (30).
"""

import os
import statistics
import sys
import time

import bpy
from mathutils import Vector

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests"))
import checks  # noqa: E402  (the add-on and the module, from the source tree)
from checks import core, voxwarp, voxwarp_blender  # noqa: E402

repeats = int(sys.argv[sys.argv.index("--") + 1]) if "--" in sys.argv[:-1] else 30
voxwarp_blender.register()
print(f"voxwarp {os.path.dirname(voxwarp.__file__)}, Blender {bpy.app.version_string}, {os.cpu_count()} cores, medians of {repeats}")
for preview in (64, 96, 128):
    bunny = checks.bunny_with_ear_handle(resolution=128)
    bunny.voxwarp.preview_resolution = preview
    handle = next(e for e in core.handles(bunny) if core.kind_of(e) == "handle")
    bunny.voxwarp.live = True
    tip = Vector(handle.location)
    updates = []
    for i in range(repeats):
        handle.location = tip + Vector((0, 0.02 * (i % 10), 0.01 * i))
        t = time.perf_counter()
        bpy.context.view_layer.update()  # the depsgraph handler runs the live update
        updates.append(time.perf_counter() - t)
    V, F, _ = core.source_arrays(bunny)
    edit = core.edit_of(bunny, bunny.voxwarp)
    alone = []
    for i in range(repeats):
        t = time.perf_counter()
        voxwarp.deform(V, F, edit, resolution=preview, snap=False)
        alone.append(time.perf_counter() - t)
    u, a = statistics.median(updates), statistics.median(alone)
    triangles = len(bunny.voxwarp.preview.data.polygons)
    print(f"bunny live at preview {preview}: update {1e3 * u:.1f} ms = {1 / u:.1f} updates/s ({triangles:,} triangles); "
          f"voxwarp.deform alone {1e3 * a:.1f} ms; Blender's share {100 * (u - a) / u:.0f} %")
    bunny.voxwarp.live = False
