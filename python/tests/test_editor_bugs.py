# The six editor bugs of the handles issue, each a test that failed before its fix, in headless Chromium through
# the printed URL: undo/redo after Next edit, Load edit file keeping what the page cannot show, a malformed or
# refused file leaving the page as it was, the camera reframed after a load, Before instead of a ghost over the
# result, and a target far outside the model refused.
import json
import math

import pytest

from conftest import data
from test_editor import editor_page, wait


@pytest.fixture
def box_page():
    """The editor on the 4 x 1 x 1 box at 48 in a browser: (driver, server)."""
    with editor_page(data("box.obj"), "--resolution", "48") as page:
        yield page


def load(driver, edit, name="edit.json"):
    """api.loadEdit of an edit (a dict or text): False when it was refused."""
    text = edit if isinstance(edit, str) else json.dumps(edit)
    return driver.execute_async_script("const done = arguments[2]; window.voxwarp.loadEdit(arguments[0], arguments[1]).then(done)", text, name)


def load_good(driver, edit):
    """Load an edit the page must take; its result shown."""
    assert load(driver, edit) is not False, driver.execute_script("return window.voxwarp.errors")
    assert driver.execute_script("return window.voxwarp.state.current.constraints.length") > 0


def test_undo_redo_after_next_edit_picks_on_the_edited_shape(box_page):
    driver, _ = box_page
    load_good(driver, json.load(open(data("box_bend.json"))))
    version = driver.execute_script("return window.voxwarp.resultVersion")
    driver.find_element("id", "next-edit").click()
    wait(driver, "window.voxwarp.state.edits.length === 1")
    driver.find_element("id", "undo").click()
    wait(driver, "window.voxwarp.state.edits.length === 0")
    driver.find_element("id", "redo").click()
    wait(driver, "window.voxwarp.state.edits.length === 1")
    # The bent end (where the bend took the box's x = 2 end) is there to click on, not the straight box.
    x, y = driver.execute_script("return window.voxwarp.screenOf([0.546, 2.546, 0.5])")
    hit = driver.execute_script("return window.voxwarp.pick(arguments[0], arguments[1])", x, y)
    assert hit and hit[1] > 2.0, hit
    assert driver.execute_script("return window.voxwarp.resultVersion") >= version


def test_load_keeps_control_points_weights_and_other_entries(box_page):
    driver, _ = box_page
    edit = {"lattice": {"size": 9}, "edits": [{"solver": "rigid", "preserve_volume": False, "constraints": [
        {"move": [2, 0, 0], "to": [2.2, 0.1, 0], "weight": 0.5},
        {"control_point": [4, 4, 4], "offset": [0, 0.05, 0]},
        {"pin": [-2, 0, 0], "weight": 2},
        {"frame": [-2, 0.5, 0], "rotate": {"axis": [0, 0, 1], "degrees": 5}},
    ]}]}
    load_good(driver, edit)
    saved = json.loads(driver.execute_script("return window.voxwarp.editJSON()"))
    assert saved == edit


def test_a_malformed_or_refused_file_leaves_the_page_as_it_was(box_page):
    driver, _ = box_page
    good = json.load(open(data("box_bend.json")))
    load_good(driver, good)
    before = driver.execute_script("return window.voxwarp.editJSON()")
    # Malformed: a point of two numbers. Refused by the server: an unknown field.
    for name, text, message in (("bad.json", '{"edits": [{"constraints": [{"move": [0, 0], "to": [1, 1, 1]}]}]}',
                                 "bad.json: edits[0].constraints[0].move: expected an array of three finite numbers"),
                                ("odd.json", '{"edits": [{"constraints": [{"move": [0, 0, 0], "to": [1, 1, 1], "speed": 2}]}]}',
                                 "odd.json: edits[0].constraints[0].speed: unknown field")):
        assert load(driver, text, name) in (False, None)  # None: a page that says nothing
        status = driver.execute_script("return document.getElementById('status').textContent")
        assert status.startswith(message), status
        assert driver.execute_script("return window.voxwarp.editJSON()") == before
        positions = driver.execute_script("return window.voxwarp.state.current.constraints.flatMap(c => (c.point || []).concat(c.to || []))")
        assert positions and all(math.isfinite(x) for x in positions)


def test_loading_reframes_the_camera_on_the_handles(box_page):
    driver, _ = box_page
    load_good(driver, json.load(open(data("box_bend.json"))))
    w, h = driver.execute_script("const r = document.getElementById('view').getBoundingClientRect(); return [r.width, r.height]")
    for c in driver.execute_script("return window.voxwarp.state.current.constraints"):
        for p in (c["point"], c.get("to", c["point"])):
            x, y = driver.execute_script("return window.voxwarp.screenOf(arguments[0])", p)
            assert 0 <= x <= w and 0 <= y <= h, (p, x, y, w, h)


def test_before_after_instead_of_a_ghost_over_the_result(box_page):
    driver, _ = box_page
    load_good(driver, json.load(open(data("box_bend.json"))))
    assert driver.execute_script("return window.voxwarp.visible()") == {"source": False, "result": True}
    driver.find_element("id", "before").click()
    assert driver.execute_script("return window.voxwarp.visible()") == {"source": True, "result": False}
    driver.find_element("id", "before").click()
    assert driver.execute_script("return window.voxwarp.visible()") == {"source": False, "result": True}


def test_a_target_far_outside_the_model_is_refused(box_page):
    driver, _ = box_page
    load(driver, {"edits": [{"constraints": [{"move": [2, 0, 0], "to": [9, 0, 0]}, {"pin": [-2, 0, 0]}]}]}, "far.json")
    status = driver.execute_script("return document.getElementById('status').textContent")
    assert status.startswith("far.json: edits[0].constraints[0].to: target (9.000000, 0.000000, 0.000000) lies more than the model's size"), status
    assert driver.execute_script("return window.voxwarp.state.current.constraints.length") == 0
