"""A drag in the editor, frames a second: `voxwarp edit` on the bunny at 128 (previews at 64) in headless Chromium
(SwiftShader), the bundled ear edit loaded, its handle dragged by pointer moves every 16 ms for two seconds, as a
mouse would (WebDriver's own actions deliver only a few moves a second). Prints each drag's shown updates per
second and their median (goal >= 5). A timing, so a benchmark: the functional test (python/tests/test_editor.py)
only checks that the result follows the drag.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/bench_drag.py [--repetitions 5]
"""
import argparse
import json
import os
import statistics
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "tests"))
from conftest import data  # noqa: E402  (the tests' server and browser helpers)
from test_editor import editor_page, pointer_drag, wait  # noqa: E402

parser = argparse.ArgumentParser()
parser.add_argument("--repetitions", type=int, default=5)
args = parser.parse_args()


with editor_page(data("bunny.obj"), "--resolution", "128") as (driver, _):
    edit = json.load(open(data("bunny_ear.json")))
    assert driver.execute_async_script("const done = arguments[2]; window.voxwarp.loadEdit(arguments[0], arguments[1]).then(done)", json.dumps(edit), "bunny_ear.json")
    rates = []
    for k in range(args.repetitions):
        wait(driver, "window.voxwarp.lastResolution === 128 && !window.voxwarp.drag.active")
        x, y = driver.execute_script("return window.voxwarp.screenOf(window.voxwarp.state.current.constraints[0].to)")
        up = 1 if k % 2 == 0 else -1  # up, then back down
        drag = pointer_drag(driver, x, y, 0.6 * up, -0.8 * up)  # as the browser test drags
        rates.append(drag["updates"] / max(drag["seconds"], 1e-9))
        print("drag: %d updates shown in %.2f s: %.1f frames a second" % (drag["updates"], drag["seconds"], rates[-1]))
    print("median %.1f frames a second over %d drags (goal >= 5)" % (statistics.median(rates), len(rates)))
