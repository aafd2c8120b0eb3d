# A real client: voxwarp's textured outputs (Spot remeshed, and with its head turned) opened by Debian's Blender,
# headless, through its own OBJ and glTF importers: one mesh, its UV map with the coordinates voxwarp wrote at the
# right corners, the material and its 1024 x 1024 texture loaded. Blender comes with the README's commands
# (scripts/setup.sh); without it this test fails rather than skips.
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

import voxwarp
from conftest import data, run_cli

SCRIPT = os.path.join(os.path.dirname(__file__), "blender_import.py")


def blender():
    path = shutil.which("blender")
    assert path, "blender is not installed: scripts/setup.sh installs it (Debian's blender, --no-install-recommends)"
    return path


def open_in_blender(mesh, tmp):
    out = str(tmp / (os.path.basename(mesh) + ".json"))
    r = subprocess.run([blender(), "-b", "--factory-startup", "--python-exit-code", "1", "--python", SCRIPT, "--", str(mesh), out],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    with open(out) as f:
        return json.load(f)


@pytest.mark.parametrize("edit", [None, "spot_head.json"])
@pytest.mark.parametrize("extension", [".obj", ".glb", ".gltf"])
def test_blender_opens_the_textured_output(edit, extension, tmp):
    (tmp / "out").mkdir()
    mesh = tmp / "out" / ("spot" + extension)
    args = ("deform", data("spot_triangulated.obj"), data(edit)) if edit else ("remesh", data("spot_triangulated.obj"))
    r = run_cli(*args, "-o", mesh, "-r", 64, "-q")
    assert r.returncode == 0, r.stderr
    V, F, A = voxwarp.read_mesh(mesh, attributes=True)
    facts = open_in_blender(mesh, tmp)
    objects = facts["objects"]
    assert len(objects) == 1, objects
    o = objects[0]
    assert o["triangles"] == len(F) and o["uv_layers"] == 1 and o["uv_count"] == 3 * len(F), {k: v for k, v in o.items() if k != "uv_samples"}
    assert [m["name"] for m in o["materials"]] == ["Spot"]
    assert o["materials"][0]["image_size"] == [1024, 1024] and o["materials"][0]["image_has_data"], o["materials"]
    # Blender's importers turn Y-up files to its Z-up: (x, y, z) in the file is (x, -z, y) in Blender. Each sampled
    # corner's texture coordinate is one that voxwarp wrote for a corner at that vertex.
    corner_uvs = {}
    for f in range(len(F)):
        for c in range(3):
            corner_uvs.setdefault(int(F[f, c]), []).append(A["uv"][A["uv_index"][f, c]])
    assert len(o["uv_samples"]) > 300
    for position, uv in o["uv_samples"]:
        p = np.array([position[0], position[2], -position[1]])
        v = int(np.argmin(((V - p) ** 2).sum(axis=1)))
        assert np.linalg.norm(V[v] - p) < 1e-5, (p, V[v])
        assert min(np.abs(np.array(uv) - u).max() for u in corner_uvs[v]) < 1e-5, (uv, corner_uvs[v])
