"""POST /api/deform against the command line for the same edit: the bundled ear edit on the bunny at 128,
`voxwarp deform` run as a process (reading the mesh, writing the output) against requests to a running
`voxwarp edit` (the first request voxelizes; later ones reuse it). Prints medians and the ratio (goal < 1.5).

    /usr/bin/python3 python/bench/bench_server.py [--resolution 128] [--repetitions 7]
"""
import argparse
import os
import re
import statistics
import subprocess
import tempfile
import time
import urllib.request

here = os.path.dirname(os.path.abspath(__file__))
root = os.path.join(here, "..", "..")
parser = argparse.ArgumentParser()
parser.add_argument("--resolution", type=int, default=128)
parser.add_argument("--repetitions", type=int, default=7)
parser.add_argument("--cli", default=os.path.join(root, "build", "bin", "voxwarp"))
args = parser.parse_args()
mesh, edit = os.path.join(root, "data", "bunny.obj"), os.path.join(root, "data", "bunny_ear.json")

cli = []
with tempfile.TemporaryDirectory() as folder:
    for _ in range(args.repetitions):
        start = time.perf_counter()
        subprocess.run([args.cli, "deform", mesh, edit, "-o", os.path.join(folder, "out.ply"), "-r", str(args.resolution), "-q"], check=True, stderr=subprocess.DEVNULL)
        cli.append(time.perf_counter() - start)

server = subprocess.Popen([args.cli, "edit", mesh, "--no-browser", "--port", "0", "-q", "-r", str(args.resolution)], stdout=subprocess.PIPE, text=True)
match = re.search(r"(http://127\.0\.0\.1:\d+/)\?token=(\w+)", server.stdout.readline())
url, token = match.group(1), match.group(2)
body = open(edit, "rb").read()
posts = []
try:
    for _ in range(args.repetitions + 1):
        start = time.perf_counter()
        with urllib.request.urlopen(urllib.request.Request(url + "api/deform", data=body, method="POST", headers={"X-Voxwarp-Token": token})) as r:
            r.read()
        posts.append(time.perf_counter() - start)
finally:
    server.terminate()
    server.wait()
c, first, p = statistics.median(cli), posts[0], statistics.median(posts[1:])
print("bunny_ear at %d: CLI %.0f ms, POST /api/deform %.0f ms (first, voxelizing: %.0f ms); ratio %.2f (first %.2f), goal < 1.5"
      % (args.resolution, 1e3 * c, 1e3 * p, 1e3 * first, p / c, first / c))
