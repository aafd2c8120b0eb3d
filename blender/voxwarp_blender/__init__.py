"""voxwarp in Blender: deform a mesh by handles (Empties) through voxwarp's volume warp, without the creases that
moving a coarse model's vertices leaves. Sidebar (N) > Voxwarp. README.md, "Blender", says how to install it."""

bl_info = {
    "name": "voxwarp",
    "author": "voxwarp",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > Voxwarp",
    "description": "Deform meshes by handles through a volume warp: voxelize, warp by a B-spline lattice, re-polygonize",
    "category": "Mesh",
}

from . import core, ui  # noqa: E402,F401


def register():
    ui.register()


def unregister():
    ui.unregister()
