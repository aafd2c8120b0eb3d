# The editor's handles that turn, in headless Chromium: a frame handle placed by clicks and set by typed numbers
# (five UI actions for the box's 90-degree bend, counted), the edit it saves giving the CLI's bytes; the view
# presets; and the work surviving a reload of the page.
import base64
import json
import math
import os

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.keys import Keys

from conftest import data, run_cli
from test_editor import editor_page, wait
from test_editor_bugs import box_page  # noqa: F401  (the fixture)


class Actions:
    """UI actions as a user makes them, counted: clicks on the canvas and the panel, typed fields."""

    def __init__(self, driver):
        self.driver, self.count = driver, 0
        self.canvas = driver.find_element("id", "view")

    def click_model(self, point):
        x, y = self.driver.execute_script("return window.voxwarp.screenOf(arguments[0])", point)
        w, h = self.canvas.size["width"], self.canvas.size["height"]
        ActionChains(self.driver).move_to_element_with_offset(self.canvas, int(x - w / 2), int(y - h / 2)).click().perform()
        self.count += 1

    def click(self, css):
        self.driver.find_element("css selector", css).click()
        self.count += 1

    def type(self, element_id, text):
        # Selected and typed over, as a user does: WebDriver's clear() fires a change of its own, a second request
        # (the field empty: the default lattice) just before the typed one. Two requests can reach the server out
        # of order; it then cancels the newer (409) and answers the older, which the page drops as superseded, and
        # nothing is shown (a 7^3 lattice once timed out so under a loaded ctest). A user's two quick changes can
        # do the same (the editor now sends the newest again: test_a_request_overtaken_on_its_way_is_sent_again).
        field = self.driver.find_element("id", element_id)
        field.send_keys(Keys.CONTROL, "a")
        field.send_keys(text + "\n")
        self.count += 1


def test_a_frame_bend_in_five_actions_saves_what_the_cli_deforms(box_page, tmp_path):  # noqa: F811
    driver, _ = box_page
    act = Actions(driver)
    act.click("input[value=frame]")
    act.click_model([-2.0, 0.0, 0.3])  # the left end's face: its frame held
    act.click_model([2.0, 0.0, 0.3])   # the right end's face
    wait(driver, "window.voxwarp.state.current.constraints.length === 2")
    act.type("sel-to", "0.546479, 2.546479, 0.3")
    act.type("sel-turn", "0, 0, 90")
    print("\nbox bent by two frame handles in %d UI actions" % act.count)
    assert act.count <= 5
    wait(driver, "window.voxwarp.state.current.constraints[1].to[1] > 2.5")
    edit = json.loads(driver.execute_script("return window.voxwarp.editJSON()"))
    frames = edit["edits"][0]["constraints"]
    assert [next(iter(c)) for c in frames] == ["frame", "frame"]
    assert frames[0]["frame"][0] < -1.5 and "rotate" not in frames[0]  # on the box near its ends: what the view shows of them
    assert frames[1]["frame"][0] > 1.5 and frames[1]["to"] == [0.546479, 2.546479, 0.3]
    rotate = frames[1]["rotate"]
    assert abs(rotate["degrees"] - 90) < 1e-6 and abs(abs(rotate["axis"][2]) - 1) < 1e-9, rotate
    # The result shown is the CLI's deform of the saved edit, byte for byte.
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON() && window.voxwarp.lastResolution === 48")  # the turned frame's result
    shown = base64.b64decode(wait(driver, "window.voxwarp.lastPlyBase64()"))
    (tmp_path / "edit.json").write_text(json.dumps(edit))
    r = run_cli("deform", data("box.obj"), tmp_path / "edit.json", "-o", tmp_path / "cli.ply", "-r", 48, "-q")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "cli.ply").read_bytes() == shown
    # A turned handle made the edit rigid, and the bend lands where the handles issue asks: within mean 0.5 and max
    # 2 voxels (the editor's, 1/12) of the analytic arc, volume within 2 %.
    assert edit["edits"][0]["solver"] == "rigid" and "solver rigid: a handle turns" in driver.execute_script("return window.voxwarp.notes")
    bent_box_obj(tmp_path / "arc.obj")
    r = run_cli("compare", tmp_path / "cli.ply", tmp_path / "arc.obj", "--voxel", 1 / 12, "--json")
    assert r.returncode == 0, r.stderr
    facts = json.loads(r.stdout)
    distance = facts["distance"]["symmetric"]["voxels"]
    print("editor bend against the arc: mean %.3f, max %.3f voxels, volume %+.2f %%" % (distance["mean"], distance["max"], 100 * (facts["a"]["enclosed_volume"] / 4 - 1)))
    assert distance["mean"] <= 0.5 and distance["max"] <= 2, distance
    assert abs(facts["a"]["enclosed_volume"] / 4 - 1) <= 0.02 and facts["a"]["closed"] and facts["a"]["components"] == 1


def bent_box_obj(path, n=40, length=4.0, width=1.0):
    """The length x width x width box bent 90 degrees into a circular arc in the x-y plane, towards +y: its centre
    line keeps its length, its cross-sections stay planar and square to it, the end x = -length/2 stays put.
    n quads per unit along each face (open at the box's edges: a distance reference, not a solid)."""
    R = length / (math.pi / 2)

    def bend(p):
        x, y, z = p
        t = (x + length / 2) / R
        return (-length / 2 + (R - y) * math.sin(t), R - (R - y) * math.cos(t), z)
    lo, hi = (-length / 2, -width / 2, -width / 2), (length / 2, width / 2, width / 2)
    verts, faces = [], []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        nu, nv = max(1, round(n * (hi[u] - lo[u]))), max(1, round(n * (hi[v] - lo[v])))
        for side in (lo[axis], hi[axis]):
            base = len(verts)
            for i in range(nu + 1):
                for j in range(nv + 1):
                    p = [0.0, 0.0, 0.0]
                    p[axis], p[u], p[v] = side, lo[u] + (hi[u] - lo[u]) * i / nu, lo[v] + (hi[v] - lo[v]) * j / nv
                    verts.append(bend(p))
            for i in range(nu):
                for j in range(nv):
                    a, b = base + i * (nv + 1) + j, base + (i + 1) * (nv + 1) + j
                    faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    with open(path, "w") as f:
        f.writelines("v %.9f %.9f %.9f\n" % q for q in verts)
        f.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in faces)


def test_view_presets_look_along_the_axes(box_page):  # noqa: F811
    driver, _ = box_page
    for button, direction in (("view-front", [0, 0, -1]), ("view-side", [-1, 0, 0]), ("view-top", [0, -1, 0])):
        driver.find_element("id", button).click()
        d = driver.execute_script("return window.voxwarp.cameraDirection()")
        assert sum(a * b for a, b in zip(d, direction)) > 0.999, (button, d)
    # Frame selected: the selected handle fills more of the view than with the whole model framed.
    Actions(driver).click("input[value=pin]")
    Actions(driver).click_model([2.0, 0.0, 0.3])
    wait(driver, "window.voxwarp.state.current.constraints.length === 1")
    driver.execute_script("window.voxwarp.select(0)")
    span = ("const a = window.voxwarp.screenOf([1.8, 0, 0.3]), b = window.voxwarp.screenOf([2.2, 0, 0.3]);"
            "return Math.hypot(a[0] - b[0], a[1] - b[1])")  # pixels across 0.4 along x, seen from the top
    driver.find_element("id", "view-all").click()
    far = driver.execute_script(span)
    driver.find_element("id", "view-selected").click()
    near = driver.execute_script(span)
    assert near > 2 * far > 0, (near, far)


def test_the_work_survives_a_reload_of_the_page(box_page):  # noqa: F811
    driver, _ = box_page
    act = Actions(driver)
    act.click("input[value=pin]")
    act.click_model([2.0, 0.0, 0.3])
    wait(driver, "window.voxwarp.state.current.constraints.length === 1")
    before = driver.execute_script("return window.voxwarp.editJSON()")
    driver.refresh()
    wait(driver, "window.voxwarp && window.voxwarp.ready")
    assert driver.execute_script("return window.voxwarp.editJSON()") == before
    point = driver.execute_script("return window.voxwarp.state.current.constraints[0].point")
    assert math.isclose(point[0], 2.0, abs_tol=0.05), point


def test_the_gizmo_turns_a_frame_handle_by_snapped_steps(box_page):  # noqa: F811
    driver, _ = box_page
    act = Actions(driver)
    act.click("input[value=frame]")
    act.click_model([-2.0, 0.0, 0.3])
    act.click_model([2.0, 0.0, 0.3])
    wait(driver, "window.voxwarp.state.current.constraints.length === 2")
    assert driver.execute_script("return window.voxwarp.gizmo()") == {"attached": True, "mode": "translate"}
    act.type("sel-to", "0.546479, 2.546479, 0.3")
    act.click("#gizmo-turn")
    assert driver.execute_script("return window.voxwarp.gizmo()")["mode"] == "rotate"
    # One drag across the z ring, a little past 90 degrees: the snap makes it 90.
    (x0, y0), (x1, y1) = driver.execute_script("return window.voxwarp.gizmoTurnDrag([0, 0, 1], 94)")
    driver.execute_script(
        """
        const [x0, y0, x1, y1] = arguments;
        const canvas = document.getElementById('view'), r = canvas.getBoundingClientRect();
        const at = (x, y) => ({clientX: r.left + x, clientY: r.top + y, button: 0, bubbles: true});
        canvas.dispatchEvent(new MouseEvent('mousemove', at(x0, y0)));
        canvas.dispatchEvent(new PointerEvent('pointerdown', Object.assign(at(x0, y0), {pointerId: 9})));
        canvas.dispatchEvent(new MouseEvent('mousedown', at(x0, y0)));
        for (let i = 1; i <= 10; ++i) document.dispatchEvent(new MouseEvent('mousemove', at(x0 + (x1 - x0) * i / 10, y0 + (y1 - y0) * i / 10)));
        document.dispatchEvent(new MouseEvent('mouseup', at(x1, y1)));
        canvas.dispatchEvent(new PointerEvent('pointerup', Object.assign(at(x1, y1), {pointerId: 9})));
        """, x0, y0, x1, y1)
    act.count += 1
    print("\nbox bent by two frame handles with the gizmo in %d UI actions" % act.count)
    frames = json.loads(driver.execute_script("return window.voxwarp.editJSON()"))["edits"][0]["constraints"]
    assert len(frames) == 2, frames  # the drag added nothing
    rotate = frames[1].get("rotate")
    assert rotate and abs(rotate["degrees"] - 90) < 1e-6 and abs(abs(rotate["axis"][2]) - 1) < 1e-9, frames[1]
    assert frames[1]["to"] == [0.546479, 2.546479, 0.3]
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON() && window.voxwarp.lastResolution === 48")


def test_a_region_placed_sized_and_moved_and_one_loaded_as_it_came(box_page):  # noqa: F811
    driver, _ = box_page
    act = Actions(driver)
    act.click("input[value=region]")
    act.click_model([0.0, 0.0, 0.5])  # the box's front face, in the middle
    wait(driver, "window.voxwarp.state.current.constraints.length === 1")
    driver.execute_script("const r = document.getElementById('sel-radius'); r.value = 0.4;"
                          "r.dispatchEvent(new Event('input')); r.dispatchEvent(new Event('change'))")
    act.type("sel-to", "0, 0, 0.7")
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON() && window.voxwarp.lastResolution === 48")
    region = json.loads(driver.execute_script("return window.voxwarp.editJSON()"))["edits"][0]["constraints"][0]
    (cx, cy, cz), radius = region["region"]["sphere"]
    assert abs(cx) < 0.1 and abs(cy) < 0.1 and abs(cz - 0.5) < 1e-6 and abs(radius - 0.4) < 0.02, region  # the slider's step
    assert [round(x, 9) for x in region["translate"]] == [round(-cx, 9), round(-cy, 9), 0.2], region
    assert "rotate" not in region
    assert driver.execute_script("return window.voxwarp.errors.length") == 0
    # A region turned about a pivot, read from a file and saved back untouched.
    edit = {"lattice": {"size": 9}, "edits": [{"solver": "rigid", "preserve_volume": False, "constraints": [
        {"region": {"sphere": [[1.5, 0, 0], 0.6]}, "rotate": {"axis": [1, 0, 0], "degrees": 20, "pivot": [1.0, 0, 0]}},
        {"pin": [-2, 0, 0]}]}]}
    from test_editor_bugs import load_good
    load_good(driver, edit)
    assert json.loads(driver.execute_script("return window.voxwarp.editJSON()")) == edit
    assert driver.execute_script("return window.voxwarp.state.current.constraints[0].kind") == "region"


def test_the_lattice_is_set_from_the_panel_and_read_from_a_file(box_page):  # noqa: F811
    driver, _ = box_page
    from test_editor_bugs import load_good
    load_good(driver, json.load(open(data("box_frames.json"))))
    assert driver.execute_script("return document.getElementById('lattice-size').value") == "9, 5, 5"
    Actions(driver).type("lattice-size", "7")
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON() && window.voxwarp.lastResolution === 48")
    assert json.loads(driver.execute_script("return window.voxwarp.editJSON()"))["lattice"] == {"size": 7}
    assert driver.execute_script("return window.voxwarp.errors.length") == 0


def test_the_lattice_is_shown_on_demand_as_the_edit_solved_it(box_page):  # noqa: F811
    driver, _ = box_page
    from test_editor_bugs import load_good
    load_good(driver, json.load(open(data("box_frames.json"))))  # the bend: 9 x 5 x 5, the right end raised 2.5
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON()")
    assert not driver.execute_script("return window.voxwarp.lattice().visible")
    Actions(driver).click("#show-lattice")
    wait(driver, "window.voxwarp.latticeVersion >= 1")
    shown = driver.execute_script("return window.voxwarp.lattice()")
    assert shown["visible"]
    nx, ny, nz = shown["facts"]["size"]
    assert [nx, ny, nz] == [9, 5, 5]
    assert shown["facts"]["segments"] == (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    solved = shown["facts"]["solved"]
    layer = lambda i: [solved[i + nx * (j + ny * k)] for k in range(nz) for j in range(ny)]  # noqa: E731
    mean_y = lambda ps: sum(p[1] for p in ps) / len(ps)  # noqa: E731
    # The raised end's control points follow it up, about 2.5 above the held end's (the rigid solve leaves the
    # empty padding around the box nearly free, so the held end's outer layer swings a little about the frame).
    assert mean_y(layer(nx - 1)) - mean_y(layer(0)) > 1.5, (mean_y(layer(0)), mean_y(layer(nx - 1)))
    # Another edit on the panel redraws it: a 7^3 lattice.
    Actions(driver).type("lattice-size", "7")
    wait(driver, "window.voxwarp.lattice().facts.size[0] === 7")
    Actions(driver).click("#show-lattice")
    assert not driver.execute_script("return window.voxwarp.lattice().visible")
    assert driver.execute_script("return window.voxwarp.errors.length") == 0


def test_the_orthographic_view_has_no_perspective_and_still_picks(box_page):  # noqa: F811
    driver, _ = box_page
    driver.find_element("id", "view-front").click()  # looking along -z
    gap = ("const a = window.voxwarp.screenOf([2, 0.5, 0.5]), b = window.voxwarp.screenOf([2, 0.5, -0.5]);"
           "return Math.hypot(a[0] - b[0], a[1] - b[1])")  # pixels between two points one behind the other
    assert driver.execute_script(gap) > 3
    Actions(driver).click("#ortho")
    assert driver.execute_script("return window.voxwarp.orthographic()")
    assert driver.execute_script(gap) < 0.5
    act = Actions(driver)
    act.click("input[value=pin]")
    act.click_model([1.5, 0.2, 0.5])  # on the front face, as the orthographic view shows it
    wait(driver, "window.voxwarp.state.current.constraints.length === 1")
    point = driver.execute_script("return window.voxwarp.state.current.constraints[0].point")
    assert math.dist(point, [1.5, 0.2, 0.5]) < 0.05, point


def test_a_textured_model_is_shown_with_its_texture_before_and_after_an_edit(tmp_path):
    # Spot (a UV map and a 1024^2 texture): the page shows the model textured, and the full result of an edit too,
    # with the CLI's texture coordinates, byte for byte; a drag preview carries none and shows in the plain colour.
    from test_editor_bugs import load_good
    with editor_page(data("spot_triangulated.obj"), "--resolution", "48") as (driver, _):
        assert driver.execute_script("return window.voxwarp.dressed()") == {"source": "texture", "result": "texture"}
        size = driver.execute_async_script("const done = arguments[0]; Viewer.api('/api/texture').then(r => r.blob()).then(b => done(b.size))")
        assert size == os.path.getsize(data("spot_texture.png"))
        edit = json.load(open(data("spot_head.json")))
        load_good(driver, edit)
        wait(driver, "window.voxwarp.lastResolution === 48 && window.voxwarp.shownEdit === window.voxwarp.editJSON()")
        assert driver.execute_script("return window.voxwarp.dressed()")["result"] == "texture"
        shown = base64.b64decode(wait(driver, "window.voxwarp.lastPlyBase64()"))
        (tmp_path / "edit.json").write_text(driver.execute_script("return window.voxwarp.editJSON()"))
        r = run_cli("deform", data("spot_triangulated.obj"), tmp_path / "edit.json", "-o", tmp_path / "cli.ply", "-r", 48, "-q")
        assert r.returncode == 0, r.stderr
        assert b"property float s" in shown[:1000] and (tmp_path / "cli.ply").read_bytes() == shown
        # A preview (below the full resolution): no texture coordinates, the plain colour.
        driver.execute_async_script("const done = arguments[0]; window.voxwarp.deformAt(24).then(done)")
        assert driver.execute_script("return window.voxwarp.dressed()")["result"] == "plain"


def test_a_request_overtaken_on_its_way_is_sent_again(box_page):  # noqa: F811
    # The server cancels a running request when another arrives; two requests sent in quick succession can arrive
    # the wrong way round, the newer answered 409 and the older's answer dropped by the page as superseded: the page
    # showed neither until the next change. Here the next deform request is answered 409 at once, as if the one
    # before it had arrived later.
    driver, _ = box_page
    from test_editor_bugs import load_good
    load_good(driver, json.load(open(data("box_frames.json"))))
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON()")
    driver.execute_script("""
        const api = Viewer.api;
        let overtaken = false;
        Viewer.api = function (path, init) {
            if (!overtaken && path.startsWith('/api/deform')) {
                overtaken = true;
                return Promise.resolve(new Response('{"error": "request: superseded by a newer request"}', {status: 409}));
            }
            return api(path, init);
        };""")
    Actions(driver).type("lattice-size", "7")
    wait(driver, "window.voxwarp.shownEdit === window.voxwarp.editJSON() && JSON.parse(window.voxwarp.shownEdit).lattice.size === 7")
