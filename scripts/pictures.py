"""The README's pictures (docs/pictures/): the bundled examples before and after, the rigid solve's bend and twist
next to min-norm and the exact answer, the feature mesher on a turned cube, and the editor. Run after the
README's set-up:

    PYTHONPATH=build/python /usr/bin/python3 scripts/pictures.py

Every picture is made by `voxwarp render` (three.js in headless Chromium); the editor's by selenium.
"""
import atexit
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

import voxwarp

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
cli = os.path.join(root, "build", "bin", "voxwarp")
out = os.path.join(root, "docs", "pictures")
data = os.path.join(root, "data")
os.makedirs(out, exist_ok=True)
work = tempfile.mkdtemp(prefix="voxwarp-pictures-")
atexit.register(shutil.rmtree, work, ignore_errors=True)


def run(*args):
    subprocess.run([cli, *map(str, args), "-q"], check=True, stderr=subprocess.DEVNULL)


def deform(mesh, edit, name, *extra):
    path = os.path.join(work, name + ".ply")
    run("deform", os.path.join(data, mesh), os.path.join(data, edit), "-o", path, *extra)
    return path


def render(name, meshes, labels, view="30,20", size="1200x500"):
    run("render", *meshes, "-o", os.path.join(out, name), "--labels", ",".join(labels), "--view", view, "--size", size)
    print("wrote", os.path.join("docs", "pictures", name))


def exact_box(map_point, n=96):
    """The 4 x 1 x 1 box, finely cut, mapped through the analytic deformation: the exact answer."""
    V, F = [], []
    lo, hi = np.array([-2, -0.5, -0.5]), np.array([2, 0.5, 0.5])
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        nu, nv = (n if u == 0 else n // 4), (n if v == 0 else n // 4)
        for side in (0, 1):
            base = len(V)
            for i in range(nu + 1):
                for j in range(nv + 1):
                    p = np.zeros(3)
                    p[axis] = (lo, hi)[side][axis]
                    p[u] = lo[u] + (hi[u] - lo[u]) * i / nu
                    p[v] = lo[v] + (hi[v] - lo[v]) * j / nv
                    V.append(map_point(p))
            for i in range(nu):
                for j in range(nv):
                    a, b, c, d = base + i * (nv + 1) + j, base + (i + 1) * (nv + 1) + j, base + (i + 1) * (nv + 1) + j + 1, base + i * (nv + 1) + j + 1
                    F += [(a, b, c), (a, c, d)] if side == 1 else [(a, c, b), (a, d, c)]
    return np.array(V), np.array(F, dtype=np.int32)


R = 4 / (math.pi / 2)


def bend(p):
    x, y, z = p
    t = (x + 2) / R
    return np.array([-2 + (R - y) * math.sin(t), R - (R - y) * math.cos(t), z])


def twist(p):
    x, y, z = p
    t = (math.pi / 2) * (x + 2) / 4
    return np.array([x, y * math.cos(t) - z * math.sin(t), y * math.sin(t) + z * math.cos(t)])


for name, edit, mapping, view in (("box_bend", "box_bend.json", bend, "20,25"), ("box_twist", "box_twist.json", twist, "35,25")):
    rigid = deform("box.obj", edit, name + "_rigid")
    with open(os.path.join(data, edit)) as f:
        text = f.read().replace('"solver": "rigid"', '"solver": "min-norm"')
    edit_min = os.path.join(work, name + "_min.json")
    with open(edit_min, "w") as f:
        f.write(text)
    minimum = os.path.join(work, name + "_min.ply")
    run("deform", os.path.join(data, "box.obj"), edit_min, "-o", minimum)
    exact = os.path.join(work, name + "_exact.ply")
    voxwarp.write_mesh(exact, *exact_box(mapping))
    render(name + ".png", [minimum, rigid, exact], ["min-norm", "rigid", "exact"], view=view, size="1500x500")

# The same bend by two frame handles (data/box_frames.json), and the ten points, beside the exact arc; the ear turned
# by a region.
exact = os.path.join(work, "box_bend_exact.ply")
render("box_frames.png", [deform("box.obj", "box_frames.json", "frames"), deform("box.obj", "box_bend.json", "points"), exact],
       ["two frames", "ten points", "exact"], view="20,25", size="1500x500")
render("bunny_ear_turn.png", [os.path.join(data, "bunny.obj"), deform("bunny.obj", "bunny_ear_turn.json", "ear_turn")], ["bunny.obj", "bunny_ear_turn.json"],
       view="80,10", size="1000x500")

render("bunny_ear.png", [os.path.join(data, "bunny.obj"), deform("bunny.obj", "bunny_ear.json", "ear")], ["bunny.obj", "bunny_ear.json"], size="1000x500")
render("bar_bend.png", [os.path.join(data, "bar.obj"), deform("bar.obj", "bar_bend.json", "bar", "-r", "96")], ["bar.obj", "bar_bend.json"], view="10,25", size="1000x400")
render("snowden_nose.png", [os.path.join(data, "snowden_lo.obj"), deform("snowden_lo.obj", "snowden_nose.json", "nose", "-r", "192")],
       ["snowden_lo.obj", "snowden_nose.json"], view="40,10", size="1000x500")

# The feature mesher: a cube turned off every axis, voxelized at 32 and meshed back.
turn = np.array([[math.cos(0.47), -math.sin(0.47), 0], [math.sin(0.47), math.cos(0.47), 0], [0, 0, 1]]) @ \
    np.array([[1, 0, 0], [0, math.cos(0.66), -math.sin(0.66)], [0, math.sin(0.66), math.cos(0.66)]])
cube = os.path.join(work, "cube.obj")
V = np.array([[x, y, z] for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)]) @ turn.T
F = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]], dtype=np.int32)
voxwarp.write_mesh(cube, V, F)
meshes = []
for mesher in ("mc", "features"):
    path = os.path.join(work, "cube_" + mesher + ".ply")
    run("voxelize", cube, "-o", os.path.join(work, "cube.vdb"), "-r", 32)
    # The round trip through deform with an identity edit keeps the mesh's sharp parts as Hermite data.
    identity = os.path.join(work, "identity.json")
    with open(identity, "w") as f:
        f.write('{"edits": [{"constraints": [{"pin": [0, 0, 0]}]}]}')
    run("deform", cube, identity, "-o", path, "-r", 32, "--mesher", mesher)
    meshes.append(path)
render("cube_features.png", meshes, ["marching cubes", "--mesher features"], view="30,25", size="1000x500")

# Spot, textured, with its head turned: the output an OBJ with its .mtl, which the render reads back.
spot = os.path.join(work, "spot_head.obj")
run("deform", os.path.join(data, "spot_triangulated.obj"), os.path.join(data, "spot_head.json"), "-o", spot, "-r", "128")
render("spot_head.png", [os.path.join(data, "spot_triangulated.obj"), spot],
       ["Spot (5856 triangles; texture 1024 x 1024)", "head turned 25 degrees: voxwarp deform at 128"], view="120,12", size="1200x560")

# The editor with the ear edit loaded, as a browser shows it.
from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402

server = subprocess.Popen([cli, "edit", os.path.join(data, "bunny.obj"), os.path.join(data, "bunny_ear.json"), "--no-browser", "--port", "0", "-q"],
                          stdout=subprocess.PIPE, text=True)
url = re.search(r"(http://127\.0\.0\.1:\d+/\S*)", server.stdout.readline()).group(1)  # with its ?token=
options = webdriver.ChromeOptions()
options.binary_location = "/usr/bin/chromium"
for a in ("--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-networking", "--no-first-run",
          "--window-size=1200,720"):
    options.add_argument(a)
driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
try:
    driver.get(url)
    for _ in range(300):
        if driver.execute_script("return window.voxwarp && window.voxwarp.ready && window.voxwarp.lastResolution > 0"):
            break
        time.sleep(0.1)
    time.sleep(0.5)
    driver.save_screenshot(os.path.join(out, "editor.png"))
    print("wrote docs/pictures/editor.png")
finally:
    driver.quit()
    server.terminate()
    server.wait()
sys.exit(0)
