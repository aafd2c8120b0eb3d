"""The Python module's overhead over the C++ deform it calls: the same bundled ear edit on the bunny, timed
around voxwarp.deform (arrays in, arrays and the report dict out) against the C++ call's own time inside the
binding (report["seconds"]["total"]). Prints medians and the ratio.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/bench_overhead.py [--resolution 128] [--repetitions 9]
"""
import argparse
import os
import statistics
import time

import voxwarp

here = os.path.dirname(os.path.abspath(__file__))
data = os.path.join(here, "..", "..", "data")
parser = argparse.ArgumentParser()
parser.add_argument("--resolution", type=int, default=128)
parser.add_argument("--repetitions", type=int, default=9)
args = parser.parse_args()

V, F = voxwarp.read_mesh(os.path.join(data, "bunny.obj"))
edit = os.path.join(data, "bunny_ear.json")
voxwarp.deform(V, F, edit, resolution=args.resolution)  # warm-up
python_s, cpp_s = [], []
for _ in range(args.repetitions):
    start = time.perf_counter()
    _, _, report = voxwarp.deform(V, F, edit, resolution=args.resolution)
    python_s.append(time.perf_counter() - start)
    cpp_s.append(report["seconds"]["total"])
p, c = statistics.median(python_s), statistics.median(cpp_s)
print("voxwarp.deform bunny_ear at %d: python %.1f ms, C++ call %.1f ms (medians of %d), overhead %.2f %% (goal < 5 %%)"
      % (args.resolution, 1e3 * p, 1e3 * c, args.repetitions, 100 * (p / c - 1)))
