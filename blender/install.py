"""Run by blender/install.sh inside Blender: copy the add-on and the compiled module (with voxwarp's own shared
libraries) into the user's add-ons, enable it, save the preferences. The user's other preferences are kept:
this runs on them, not on factory settings."""

import glob
import os
import shutil
import sys

import addon_utils
import bpy

source = sys.argv[sys.argv.index("--") + 1]
addons = bpy.utils.user_resource("SCRIPTS", path="addons", create=True)
target = os.path.join(addons, "voxwarp_blender")
if os.path.isdir(target):
    addon_utils.disable("voxwarp_blender")
    shutil.rmtree(target)
shutil.copytree(os.path.join(source, "blender", "voxwarp_blender"), target, ignore=shutil.ignore_patterns("__pycache__", "lib"))
lib = os.path.join(target, "lib")
shutil.copytree(os.path.join(source, "build", "python", "voxwarp"), os.path.join(lib, "voxwarp"), ignore=shutil.ignore_patterns("__pycache__"))
for library in glob.glob(os.path.join(source, "build", "lib*", "libvoxwarp_*.so*")):
    shutil.copy2(library, lib, follow_symlinks=True)
bpy.utils.refresh_script_paths()  # a user add-ons folder made just now joins sys.path
addon_utils.modules_refresh()
if addon_utils.enable("voxwarp_blender", default_set=True, persistent=True) is None:
    sys.exit("voxwarp: the add-on did not enable (Blender's message above)")
from voxwarp_blender import core  # noqa: E402

voxwarp = core.module()
bpy.ops.wm.save_userpref()
print(f"voxwarp: add-on installed in {target} (module {os.path.dirname(voxwarp.__file__)}), enabled; Sidebar (N) > Voxwarp")
