# voxwarp's Blender add-on (blender/voxwarp_blender) driven through its operators in Debian's Blender, headless:
# the 4 x 1 x 1 box bent 90 degrees by two handles against the analytic arc (and Blender's own Simple Deform on the
# same box against the same arc), Live mode, Undo (in a window under xvfb-run), edit files both ways with the CLI
# giving the same bytes, bad input reported without a crash, and the one-command install. Each check runs in its
# own Blender (blender/tests/checks.py) and writes its figures; the judging is here. Blender and xvfb come with the
# README's commands (scripts/setup.sh); without them these tests fail rather than skip.
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

import voxwarp
from conftest import data, run_cli

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
CHECKS = os.path.join(ROOT, "blender", "tests", "checks.py")
MODULE = os.path.dirname(os.path.dirname(os.path.abspath(voxwarp.__file__)))


def tool(name):
    path = shutil.which(name)
    assert path, f"{name} is not installed: scripts/setup.sh installs it"
    return path


def rotation(rotate):
    """The matrix of an edit file's {"axis", "degrees"} (Rodrigues)."""
    k = np.array(rotate["axis"], float) / np.linalg.norm(rotate["axis"])
    a = np.radians(rotate["degrees"])
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def check(name, tmp, window=False):
    """Figures of one check in blender/tests/checks.py."""
    out = tmp / f"{name}.json"
    command = [tool("blender"), "--factory-startup", "--python-exit-code", "1", "--python", CHECKS, "--", name, str(out)]
    if window:  # undo needs a window: a virtual X display, software OpenGL
        command = [tool("xvfb-run"), "-a", "-s", "-screen 0 1280x800x24"] + command
    else:
        command.insert(1, "-b")
    env = dict(os.environ, VOXWARP_PYTHONPATH=MODULE)
    r = subprocess.run(command, capture_output=True, text=True, timeout=600, env=env)
    assert out.exists(), r.stdout[-3000:] + r.stderr[-3000:]
    figures = json.loads(out.read_text())
    assert "exception" not in figures, figures["exception"]
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return figures


def test_box_bent_by_two_handles_lands_on_the_arc(tmp):
    f = check("bend", tmp)
    v, coarse, fine = f["voxwarp"], f["simple_deform"], f["simple_deform_subdivided"]
    print(f"box bent 90 degrees at voxel {f['voxel_size']}: voxwarp ({f['handles']} handles, {v['triangles']} triangles) mean {v['mean']:.3f} "
          f"p99 {v['p99']:.3f} max {v['max']:.3f} voxel, volume {v['volume_change_percent']:+.2f} %; Simple Deform ({coarse['triangles']} triangles) "
          f"mean {coarse['mean']:.3f} p99 {coarse['p99']:.3f} max {coarse['max']:.3f}; Simple Deform subdivided ({fine['triangles']}) mean "
          f"{fine['mean']:.4f} max {fine['max']:.4f}; {f['seconds']:.2f} s")
    assert f["handles"] == 2
    # The bar is 1 voxel mean; measured 0.165 mean, 0.99 max, +1.49 % volume (two frames, lattice 9 x 5 x 5;
    # before the frames gripped the end faces as plates, 0.100 / 0.92 / +1.38 %).
    assert v["mean"] <= 0.2 and v["max"] <= 1.9 and abs(v["volume_change_percent"]) <= 2.0, v
    # Simple Deform puts each vertex on the same analytic map (so its subdivided box lies on the arc: this checks
    # that the arc is placed where both tools bend to), and the coarse box's flat faces far off it.
    assert fine["mean"] <= 0.05 and fine["max"] <= 0.5, fine
    assert coarse["mean"] >= 10 * v["mean"], (coarse, v)


def test_live_mode_follows_the_handle_then_finishes_at_full_resolution(tmp):
    f = check("live", tmp)
    updates = f["updates"]
    assert f["live_object"] and len(updates) == 12
    assert all(u["status"].startswith("preview: ") and u["vertices"] > 1000 for u in updates), updates
    # The handle rose 0.6 over the moves: so did the ear's tip, each preview after the last (within a voxel, 0.15).
    assert updates[-1]["top"] - updates[0]["top"] > 0.3 and all(b["top"] > a["top"] - 0.15 for a, b in zip(updates, updates[1:])), updates
    assert not f["full"]["status"].startswith("preview") and f["full"]["vertices"] > 2 * updates[-1]["vertices"], f["full"]
    assert f["full_matches_apply"]
    assert f["live_object_after_off"] == 0


def test_undo_returns_the_original_after_the_ear_is_pulled(tmp):
    f = check("undo", tmp, window=True)
    pulled = f["in_place"]
    assert pulled["after"] != pulled["before"] and pulled["top_after"] > pulled["top_before"] + 1.0, pulled  # the ear went up 1.55
    assert f["undone"]["vertices"] == pulled["before"] and f["undone"]["max_difference"] == 0.0, f["undone"]
    assert f["undone"]["rest_of_handle"] == f["rest_before"]
    assert f["new_objects"] == ["bunny voxwarp"] and f["after_undo"] == []


def test_an_edit_file_from_blender_gives_the_same_bytes_through_the_cli(tmp):
    f = check("files", tmp)
    # The bundled edit, imported as handles and exported: the same constraints, to the last digit.
    original = json.load(open(data("bunny_ear.json")))
    exported = json.load(open(f["roundtrip"]))
    assert f["imported_handles"] == 4
    assert exported["edits"][0]["constraints"] == original["edits"][0]["constraints"]
    assert exported["lattice"] == original["lattice"]
    # Frames (one turned) and regions (a sphere turned about a pivot; a box, which no Empty shows, kept as it is).
    for name in ("box_frames.json", "bunny_ear_turn.json"):
        original = json.load(open(data(name)))
        again = json.load(open(f["again_" + name]))
        assert again["lattice"]["size"] == [original["lattice"]["size"]] * 3 or again["lattice"]["size"] == original["lattice"]["size"]
        assert again["edits"][0]["solver"] == original["edits"][0]["solver"]
        for a, b in zip(original["edits"][0]["constraints"], again["edits"][0]["constraints"]):
            assert next(iter(a)) == next(iter(b)), (a, b)
            if "frame" in a:
                assert b["frame"] == a["frame"] and b["to"] == pytest.approx(a.get("to", a["frame"]), abs=1e-6), (a, b)
                assert ("rotate" in a) == ("rotate" in b)
                if "rotate" in a:
                    assert b["rotate"]["degrees"] == pytest.approx(a["rotate"]["degrees"], abs=1e-4)
                    assert b["rotate"]["axis"] == pytest.approx(a["rotate"]["axis"], abs=1e-6)
            elif "sphere" in a["region"]:
                # The Empty rests at the centre: the same motion, written about the centre.
                assert b["region"]["sphere"][0] == pytest.approx(a["region"]["sphere"][0], abs=1e-6)
                assert b["region"]["sphere"][1] == pytest.approx(a["region"]["sphere"][1], abs=1e-6)
                assert b["rotate"]["degrees"] == pytest.approx(a["rotate"]["degrees"], abs=1e-4)
                assert b["rotate"]["pivot"] == pytest.approx(a["region"]["sphere"][0], abs=1e-6)
                R = rotation(a["rotate"])
                c, p = np.array(a["region"]["sphere"][0]), np.array(a["rotate"]["pivot"])
                assert np.array(b["translate"]) == pytest.approx(R @ (c - p) + p - c, abs=1e-5)
            else:
                assert b == a
    # Handles moved, turned, a region: the CLI, given the exported edit file and mesh, writes Blender's bytes.
    edit = json.load(open(f["edit"]))["edits"][0]["constraints"]
    assert [next(iter(c)) for c in edit] == ["frame", "pin", "pin", "pin", "region"], edit  # the turned handle a frame
    assert "rotate" in edit[0] and "rotate" not in edit[4] and "translate" not in edit[4], edit
    out = tmp / "cli.obj"
    r = run_cli("deform", f["mesh"], f["edit"], "-o", out, "-q", *f["options"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == open(f["output"], "rb").read()


def test_bad_input_is_reported_and_blender_carries_on(tmp):
    f = check("errors", tmp)
    assert "empty: the mesh has no faces" in f["empty_mesh"]["error"]
    assert "box: no handles" in f["no_handles"]["error"]
    assert "lies far outside the model" in f["handle_outside"]["error"], f["handle_outside"]
    assert "bad_edit.json: edits[0].constraints[0].move: expected an array of three" in f["malformed_edit"]["error"]
    assert f["handles_after_malformed"] == 2  # a bad file changes nothing
    assert f["open_scan"] == {"result": ["FINISHED"]}
    assert "scan voxwarp" in f["objects"] and "box voxwarp" not in f["objects"]


def test_one_command_installs_and_enables_the_addon(tmp):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VOXWARP_PYTHONPATH")}
    env.update(BLENDER_USER_SCRIPTS=str(tmp / "scripts"), BLENDER_USER_CONFIG=str(tmp / "config"))
    r = subprocess.run(["bash", os.path.join(ROOT, "blender", "install.sh")], capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "add-on installed" in r.stdout
    # A new Blender with those preferences has it enabled, and its module loads voxwarp's libraries it ships.
    probe = ("import addon_utils, json, sys; from voxwarp_blender import core; m = core.module(); "
             "maps = open('/proc/self/maps').read(); "
             "json.dump({'enabled': addon_utils.check('voxwarp_blender'), 'module': m.__file__, "
             "'libraries': sorted({l.split()[-1] for l in maps.splitlines() if 'libvoxwarp_' in l})}, open(sys.argv[-1], 'w'))")
    out = tmp / "probe.json"
    r = subprocess.run([tool("blender"), "-b", "--python-exit-code", "1", "--python-expr", probe, "--", str(out)], capture_output=True, text=True,
                       timeout=300, env=env)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    facts = json.loads(out.read_text())
    addon = str(tmp / "scripts" / "addons" / "voxwarp_blender")
    assert facts["enabled"] == [True, True], facts
    assert facts["module"].startswith(addon), facts
    assert facts["libraries"] and all(path.startswith(addon) for path in facts["libraries"]), facts


def test_apply_keeps_the_material_uv_map_and_colour(tmp):
    f = check("attributes", tmp)
    print(f"Spot through Apply at 64: UV to the source's {f['uv_texels']}, colour {f['colour']}")
    assert f["materials"] == f["source_materials"] == ["Spot"]
    assert f["uv_layers"] == 1 and f["colour_layers"] == 1 and f["triangles"] > 10000
    # Measured: UV median 6e-5 texel, p90 1.3e-4; colour (a linear function of position) median 7e-5, p99 0.0023.
    assert f["uv_texels"]["median"] <= 0.01 and f["uv_texels"]["p90"] <= 0.1, f["uv_texels"]
    assert f["colour"]["median"] <= 0.001 and f["colour"]["p99"] <= 0.005, f["colour"]


def test_apply_keeps_custom_split_normals(tmp):
    f = check("normals", tmp)
    print(f"cube with rounded custom normals through Apply at 32: loop normals to the source's {f['degrees']} degrees")
    assert f["source_custom"] and f["custom"], f
    # Measured: median and p99 0, max 0.13 degree (Blender stores custom normals in 16-bit pairs). Blender's own
    # normals there (flat sides) lie up to 55 degrees off.
    assert f["degrees"]["median"] <= 0.01 and f["degrees"]["max"] <= 0.3, f["degrees"]


def test_handles_go_where_the_operators_put_them(tmp):
    f = check("handles", tmp)
    assert f["at_vertices"] == [2.0, 0.0, -0.5]  # the mean of the two selected vertices, in the mesh's own frame
    assert f["pin"] == [-2.0, 0.0, 0.0]  # the 3D cursor at world (6, 0, 0) on the box moved by 10 and scaled by 2
    assert f["parent"] == "box" and f["collection"] == ["voxwarp"]
    # The handle shown as a sphere (radius 0.1) is a region, held where it was put.
    assert f["kinds"] == ["region", "pin"]
    region, pin = f["constraints"]
    assert region["region"]["sphere"][0] == [2.0, 0.0, -0.5] and region["region"]["sphere"][1] == pytest.approx(0.1) and len(region) == 1, region
    assert pin == {"pin": [-2.0, 0.0, 0.0]}


def test_the_sidebar_panel_offers_the_settings_and_operators(tmp):
    f = check("panel", tmp)
    for active in ("bunny", "handle"):  # a handle active shows its mesh's panel
        names = [name for _, name in f[active]]
        assert names[0] == "bunny: 4 handles" and names[-1] == "a status line", names
        for name in ("resolution", "voxel_size", "solver", "preserve_volume", "mesher", "live", "preview_resolution", "voxwarp.add_handle",
                     "voxwarp.deform", "voxwarp.import_edit", "voxwarp.export_edit"):
            assert name in names, (name, names)
    assert f["nothing"] == [["label", "Select a mesh (or one of its handles)"]]
