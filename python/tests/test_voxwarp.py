# The Python module against the command line and analytic shapes: dtypes and shapes, errors and their messages,
# cancelling, the GIL, and byte-identical meshes to the CLI for the bundled examples.
import json
import os
import signal
import threading
import time

import numpy as np
import pytest

import voxwarp
from conftest import box, data, icosphere, run_cli


def test_read_mesh_gives_float64_positions_and_int32_triangles():
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    assert V.dtype == np.float64 and V.shape == (1839, 3) and V.flags["C_CONTIGUOUS"]
    assert F.dtype == np.int32 and F.shape == (3674, 3)
    assert F.min() == 0 and F.max() == len(V) - 1
    # The arrays hold the C++ vectors themselves (handed over, not copied): their memory is owned elsewhere.
    assert not V.flags["OWNDATA"] and V.base is not None


def test_write_then_read_round_trips(tmp):
    V, F = box()
    for ext in (".obj", ".ply", ".off", ".stl"):
        path = tmp / ("box" + ext)
        voxwarp.write_mesh(path, V, F)
        V2, F2 = voxwarp.read_mesh(str(path))
        assert len(F2) == 12
        np.testing.assert_allclose(np.sort(np.unique(V2, axis=0), axis=0), np.sort(V, axis=0), atol=1e-6)


def test_other_numeric_dtypes_are_accepted():
    V, F = box()
    for v, f in ((V.astype(np.float32), F.astype(np.int64)), (V, F.astype(np.uint32)), (np.asfortranarray(V), F[:, :].copy(order="F"))):
        vm = voxwarp.voxelize(v, f, resolution=16)
        assert vm.dims[0] > vm.dims[1]


@pytest.mark.parametrize(
    "V, F, message",
    [
        (np.zeros((4, 2)), np.zeros((1, 3), np.int32), "V: expected an array of shape (n, 3), got shape (4, 2)"),
        (box()[0], box()[1][:, :2], "F: expected an array of shape (m, 3), got shape (12, 2)"),
        (box()[0], box()[1].astype(np.float64), "F: expected integer vertex indices, got dtype float64"),
        (np.where(np.arange(24).reshape(8, 3) == 9, np.nan, box()[0]), box()[1], "V: vertex 3 has a non-finite coordinate"),
        (box()[0], np.vstack([box()[1], [[0, 1, 99]]]).astype(np.int32), "F: face 12 refers to vertex 99, the mesh has 8 vertices"),
        (box()[0], np.vstack([box()[1], [[0, -1, 2]]]).astype(np.int32), "F: face 12 refers to vertex -1, the mesh has 8 vertices"),
        (np.zeros((3, 3)), np.array([[0, 1, 2]], np.int32), "V: every face has zero area"),
        (np.zeros((0, 3)), np.zeros((0, 3), np.int32), "V: no vertices"),
    ],
)
def test_bad_arrays_are_refused_with_the_cli_messages(V, F, message, tmp):
    for call in (lambda: voxwarp.voxelize(V, F), lambda: voxwarp.write_mesh(tmp / "x.obj", V, F), lambda: voxwarp.deform(V, F, data("bunny_ear.json"))):
        with pytest.raises(voxwarp.InvalidInput) as e:
            call()
        assert message in str(e.value)
    assert not (tmp / "x.obj").exists()


def test_files_fail_as_on_the_command_line(tmp):
    bad = tmp / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    with pytest.raises(voxwarp.InvalidInput) as e:
        voxwarp.read_mesh(bad)
    cli = run_cli("info", bad)
    assert cli.returncode == 2 and str(e.value) in cli.stderr
    with pytest.raises(voxwarp.IOError) as missing:
        voxwarp.read_mesh(tmp / "missing.obj")
    assert isinstance(missing.value, OSError) and "no such file" in str(missing.value)
    edit = tmp / "bad.json"
    edit.write_text('{"edits": [{"constraints": [{"move": [0, 0, "x"], "to": [0, 1, 0]}]}]}')
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    with pytest.raises(voxwarp.InvalidInput) as e:
        voxwarp.deform(V, F, str(edit), resolution=32)
    assert "bad.json: edits[0].constraints[0].move[2]: expected a number" in str(e.value)
    cli = run_cli("deform", data("bunny.obj"), edit, "-o", tmp / "out.obj", "-q")
    assert cli.returncode == 2 and str(e.value) in cli.stderr


def test_error_classes_form_a_hierarchy():
    assert issubclass(voxwarp.InvalidInput, voxwarp.Error) and issubclass(voxwarp.InvalidInput, ValueError)
    assert issubclass(voxwarp.ResourceLimit, voxwarp.Error) and issubclass(voxwarp.ResourceLimit, MemoryError)
    assert issubclass(voxwarp.IOError, OSError)
    for cls in (voxwarp.SolverFailure, voxwarp.Cancelled, voxwarp.Error):
        assert issubclass(cls, RuntimeError)


def test_memory_hungry_requests_are_refused_up_front():
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    with pytest.raises(voxwarp.ResourceLimit) as e:
        voxwarp.voxelize(V, F, resolution=4096, max_memory=0.01)
    assert "GiB" in str(e.value) or "MiB" in str(e.value)


def test_voxmap_density_is_a_view_in_index_order():
    V, F = icosphere(3, 1.0)
    vm = voxwarp.voxelize(V, F, voxel_size=0.05)
    d = vm.density
    assert d.dtype == np.float32 and d.shape == vm.dims and d.flags["F_CONTIGUOUS"]
    # density[i, j, k] is voxel (i, j, k), centred at origin + h (i, j, k): the centre voxel is inside.
    centre = np.round((np.zeros(3) - np.array(vm.origin)) / vm.voxel_size).astype(int)
    assert d[tuple(centre)] == pytest.approx(1.0)
    assert d[0, 0, 0] == 0.0
    volume = vm.enclosed_volume()
    assert volume == pytest.approx(4 / 3 * np.pi * 0.99, rel=0.03)  # the icosphere's chords cut a little off
    d[:] = 0  # a view: writing through it empties the voxmap
    assert vm.enclosed_volume() == 0


def test_voxmap_from_numpy_extracts_the_sphere_it_holds():
    n, h = 40, 0.1
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    origin = np.array([-2.0, -2.0, -2.0])
    r = np.sqrt(((origin + h * np.stack([i, j, k], -1)) ** 2).sum(-1))
    density = np.clip(0.5 - (r - 1.3) / (2 * h), 0, 1)  # the voxelizer's ramp around a sphere of radius 1.3
    vm = voxwarp.Voxmap(density, origin=origin, voxel_size=h)
    V, F = voxwarp.extract(vm)
    assert V.dtype == np.float64 and F.dtype == np.int32
    assert np.abs(np.linalg.norm(V, axis=1) - 1.3).max() < 0.05 * h * 10  # within half a voxel everywhere
    assert np.abs(np.linalg.norm(V, axis=1) - 1.3).mean() < 0.05 * h
    with pytest.raises(voxwarp.InvalidInput, match="density: holds non-finite values"):
        voxwarp.Voxmap(np.full((4, 4, 4), np.nan))
    with pytest.raises(voxwarp.InvalidInput, match=r"density: expected an array of shape \(nx, ny, nz\)"):
        voxwarp.Voxmap(np.zeros((4, 4)))


@pytest.mark.parametrize("mesh, edit, resolution", [("bunny.obj", "bunny_ear.json", 64), ("bunny.obj", "bunny_ear.json", 128), ("box.obj", "box_bend.json", 48)])
def test_deform_is_byte_identical_to_the_cli(mesh, edit, resolution, tmp):
    cli_out, py_out = tmp / "cli.ply", tmp / "py.ply"
    r = run_cli("deform", data(mesh), data(edit), "-o", cli_out, "-r", resolution, "-q", "--report", tmp / "cli.json")
    assert r.returncode == 0, r.stderr
    V, F = voxwarp.read_mesh(data(mesh))
    V2, F2, report = voxwarp.deform(V, F, data(edit), resolution=resolution)
    voxwarp.write_mesh(py_out, V2, F2)
    assert cli_out.read_bytes() == py_out.read_bytes()
    cli_report = json.loads((tmp / "cli.json").read_text())
    assert set(report) == set(cli_report) - {"input", "edits_file", "output"}
    assert report["edits"][0]["constraints"] == cli_report["edits"][0]["constraints"]
    # A dict in the edit-file schema is the same edit.
    with open(data(edit)) as f:
        V3, F3, _ = voxwarp.deform(V, F, json.load(f), resolution=resolution)
    assert np.array_equal(V2, V3) and np.array_equal(F2, F3)


def test_deform_reports_like_the_cli():
    V, F = box()
    V2, F2, report = voxwarp.deform(V, F, data("box_twist.json"), resolution=48)
    assert report["edits"][0]["solver"] == "rigid"
    assert abs(report["volume_change_percent"]) < 2
    moves = [c for c in report["edits"][0]["constraints"] if c["kind"] == "move"]
    assert moves and all(c["surface_miss_voxels"] is not None for c in moves)
    assert report["output_faces"] == len(F2) and report["output_vertices"] == len(V2)
    assert report["snap"] and report["snapped_vertices"] + report["partly_snapped_vertices"] + report["unsnapped_vertices"] == len(V2)
    # snap=False: vertices where extraction put them. Snapped: the same vertices moved, then those refinement put
    # on edges across the box's edges.
    V3, F3, plain = voxwarp.deform(V, F, data("box_twist.json"), resolution=48, snap=False)
    assert not plain["snap"] and plain["snapped_vertices"] == 0 and plain["refined_vertices"] == 0
    assert report["refined_vertices"] > 0 and len(V2) == len(V3) + report["refined_vertices"]
    assert len(F2) > len(F3) and not np.array_equal(V2[: len(V3)], V3)
    # Snapping moves a vertex at most half a voxel, except around a move's target, whose nearest vertex goes onto
    # it (anchors, within 1.5 voxels) with the vertices within three times that pull (at least 1.5 voxels) following.
    h = report["voxel_size"]
    with open(data("box_twist.json")) as f:
        targets = np.array([c["to"] for e in json.load(f)["edits"] for c in e["constraints"] if "to" in c and "move" in c])
    near = (np.linalg.norm(V3[:, None, :] - targets[None, :, :], axis=2) <= 6.0 * h).any(axis=1)
    moved = np.linalg.norm(V2[: len(V3)] - V3, axis=1)
    assert moved[~near].max() <= 0.5 * h * (1 + 1e-9)
    assert moved.max() <= 2.0 * h * (1 + 1e-9)  # 1.5 voxels of pull beyond a snap of at most half a voxel
    # The corners the edit drags lie on the output (unsnapped, marching cubes rounds them off by 0.9-1.0 voxel).
    assert all(c["surface_miss_voxels"] <= 0.01 for c in moves)


def _turned_box():
    V, F = box((-1, -0.6, -0.4), (1, 0.6, 0.4))
    a, b = np.radians(20), np.radians(35)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return V @ (Rx @ Rz).T, F


def _corner_miss(V_out, corners):
    """Distance from each corner of the input box to the nearest output vertex."""
    return np.array([np.linalg.norm(V_out - c, axis=1).min() for c in corners])


def test_feature_mesher_keeps_corners_and_matches_the_cli(tmp):
    V, F = _turned_box()
    edit = {"edits": [{"constraints": [{"pin": [float(x) for x in V[0]]}]}]}
    resolution = 24
    _, _, report = voxwarp.deform(V, F, edit, resolution=resolution)
    h = report["voxel_size"]
    misses = {}
    for mesher in ("mc", "features"):
        V2, F2, _ = voxwarp.deform(V, F, edit, resolution=resolution, mesher=mesher, snap=False)
        misses[mesher] = _corner_miss(V2, V) / h
    # Unsnapped, marching cubes cuts every corner off; the feature mesher puts a vertex on it.
    assert misses["features"].max() < 0.15, misses
    assert misses["mc"].min() > 0.3, misses
    # Snapped (the default), either way: refinement puts the input's corners in.
    V2, F2, _ = voxwarp.deform(V, F, edit, resolution=resolution)
    assert (_corner_miss(V2, V) / h).max() < 0.01
    # The same call from the command line writes the same bytes.
    voxwarp.write_mesh(tmp / "in.ply", V, F)
    (tmp / "edit.json").write_text(json.dumps(edit))
    r = run_cli("deform", tmp / "in.ply", tmp / "edit.json", "-o", tmp / "cli.ply", "-r", resolution, "--mesher", "features", "-q")
    assert r.returncode == 0, r.stderr
    Vf, Ff = voxwarp.read_mesh(tmp / "in.ply")  # what the command line read (PLY holds float32)
    V3, F3, _ = voxwarp.deform(Vf, Ff, edit, resolution=resolution, mesher="FEATURES")
    voxwarp.write_mesh(tmp / "py.ply", V3, F3)
    assert (tmp / "cli.ply").read_bytes() == (tmp / "py.ply").read_bytes()
    vm = voxwarp.voxelize(V, F, resolution=resolution)
    # From a voxmap alone the normals come from the density's gradient: nearer the corners than marching cubes.
    extracted = {m: _corner_miss(voxwarp.extract(vm, mesher=m)[0], V) / vm.voxel_size for m in ("mc", "features")}
    assert extracted["features"].mean() < extracted["mc"].mean(), extracted
    for call in (lambda: voxwarp.deform(V, F, edit, mesher="dual"), lambda: voxwarp.extract(vm, mesher="")):
        with pytest.raises(voxwarp.InvalidInput, match='mesher: expected "mc" or "features", got'):
            call()


def test_thin_parts_are_reported():
    # A cube and a plate 0.3 voxel thick between two planes of voxel centres (resolution 24 over 5 units).
    h = 5 / 24
    V1, F1 = box((0, 0, 0), (2, 2, 2))
    V2, F2 = box((3, 0.2, 4.35 * h), (5, 1.8, 4.65 * h))
    V, F = np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)]).astype(np.int32)
    edit = {"edits": [{"constraints": [{"pin": [0.0, 0.0, 0.0]}]}]}
    # sign="auto" sees the flood fill lose the plate and keeps it by winding numbers; a flood fill by name loses it.
    _, _, kept = voxwarp.deform(V, F, edit, resolution=24)
    assert kept["sign"] == "winding-number" and "flood fill" in kept["sign_note"] and not kept["thin_parts"]
    _, _, report = voxwarp.deform(V, F, edit, resolution=24, sign="flood-fill")
    assert report["sign"] == "flood-fill"
    (part,) = report["thin_parts"]
    assert part["stage"] == "voxelize" and abs(part["thickness_voxels"] - 0.3) < 0.02
    assert np.linalg.norm(np.array(part["centre"]) - [4, 1, 4.5 * h]) < h
    assert part["resolution_to_keep"] > 24


def test_malformed_edit_dicts_name_their_json_path():
    V, F = box()
    with pytest.raises(voxwarp.InvalidInput, match=r'edit: edits\[0\]\.solver: expected "min-norm" or "rigid", got "arap"'):
        voxwarp.deform(V, F, {"edits": [{"constraints": [{"pin": [0, 0, 0]}], "solver": "arap"}]})
    with pytest.raises(voxwarp.InvalidInput, match="edit: expected a dict"):
        voxwarp.deform(V, F, 42)


def test_progress_reports_and_cancels():
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    seen = []

    def record(stage, fraction):
        seen.append((stage, fraction))
        return True

    voxwarp.deform(V, F, data("bunny_ear.json"), resolution=64, progress=record)
    assert seen and all(isinstance(s, str) and 0 <= f <= 1 for s, f in seen)
    with pytest.raises(voxwarp.Cancelled):
        voxwarp.deform(V, F, data("bunny_ear.json"), resolution=64, progress=lambda s, f: False)

    def boom(stage, fraction):
        raise ZeroDivisionError("from the callback")

    with pytest.raises(ZeroDivisionError, match="from the callback"):
        voxwarp.voxelize(V, F, resolution=64, progress=boom)


def test_ctrl_c_cancels_a_long_call():
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    start = time.perf_counter()
    voxwarp.deform(V, F, data("bunny_ear.json"), resolution=512, snap=False)
    whole = time.perf_counter() - start  # the same call left alone, in this run
    timer = threading.Timer(0.1 * whole, os.kill, (os.getpid(), signal.SIGINT))
    start = time.perf_counter()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        voxwarp.deform(V, F, data("bunny_ear.json"), resolution=512, snap=False)
    stopped = time.perf_counter() - start
    timer.join()
    # Interrupted at a tenth of the way, it stops well before the end (a call that ignored Ctrl-C would run its
    # whole course and raise afterwards).
    assert stopped < 0.6 * whole, (stopped, whole)
    # Python's own Ctrl-C handling is back afterwards.
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_long_calls_release_the_gil():
    V, F = voxwarp.read_mesh(data("bunny.obj"))
    ticks = [0]
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks[0] += 1
            time.sleep(0.001)

    counter = threading.Thread(target=count)
    counter.start()
    before = ticks[0]
    voxwarp.deform(V, F, data("bunny_ear.json"), resolution=128)
    during = ticks[0] - before
    stop.set()
    counter.join()
    assert during > 20  # a call holding the GIL would have let the counter run not at all


def test_attributes_come_through_deform_and_files_as_arrays(tmp):
    V, F, A = voxwarp.read_mesh(data("spot_triangulated.obj"), attributes=True)
    assert A["uv"].dtype == np.float64 and A["uv"].shape == (3225, 2)
    assert A["uv_index"].dtype == np.int32 and A["uv_index"].shape == F.shape
    assert A["material"].shape == (len(F),) and (A["material"] == 0).all()
    assert A["materials"][0]["name"] == "Spot" and os.path.samefile(A["materials"][0]["texture"], data("spot_texture.png"))
    V2, F2, report, A2 = voxwarp.deform(V, F, data("spot_head.json"), resolution=64, attributes=A)
    assert report["attributes"] and A2["uv_index"].shape == F2.shape and A2["material"].shape == (len(F2),)
    assert A2["uv_index"].min() >= 0 and A2["uv_index"].max() < len(A2["uv"])
    # The same run without attributes gives the same geometry but for the vertices added on seams.
    V3, F3, _ = voxwarp.deform(V, F, data("spot_head.json"), resolution=64)
    assert len(F2) - len(F3) == 2 * (len(V2) - len(V3)) > 0
    assert np.array_equal(V2[: len(V3)], V3)
    # Written as OBJ with its .mtl, read back the same; the texture found from the output's folder.
    (tmp / "out").mkdir()
    voxwarp.write_mesh(tmp / "out" / "cow.obj", V2, F2, A2)
    V4, F4, A4 = voxwarp.read_mesh(tmp / "out" / "cow.obj", attributes=True)
    assert np.array_equal(A4["uv"], A2["uv"]) and np.array_equal(A4["uv_index"], A2["uv_index"]) and np.array_equal(F4, F2)
    assert os.path.samefile(A4["materials"][0]["texture"], data("spot_texture.png"))
    with pytest.raises(voxwarp.InvalidInput, match="triangle_uvs has 5 entries, expected one per triangle"):
        voxwarp.write_mesh(tmp / "bad.obj", V2, F2, {"uv": A2["uv"], "uv_index": A2["uv_index"][:5]})
    assert not (tmp / "bad.obj").exists()
    (tmp / "nolib.obj").write_text("mtllib gone.mtl\nusemtl skin\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    with pytest.warns(UserWarning, match="gone.mtl not found"):
        _, _, A5 = voxwarp.read_mesh(tmp / "nolib.obj", attributes=True)
    assert A5["materials"][0]["name"] == "skin"


def tetrahedron_faces(V, F, h):
    """For each triangle of a remeshed corner tetrahedron (faces in the planes z = 0, y = 0, x = 0 and
    x + y + z = 1, in the order of the test files' faces): whether its centroid lies clear of the edges (two voxels
    nearer one face's plane than any other's), and the face it is nearest."""
    c = V[F].mean(axis=1)
    planes = np.abs(np.stack([c[:, 2], c[:, 1], c[:, 0], (1 - c.sum(axis=1)) / np.sqrt(3)], axis=1))
    order = np.sort(planes, axis=1)
    clear = order[:, 1] - order[:, 0] > 2 * h
    assert clear.sum() > len(F) / 2
    return clear, np.argmin(planes, axis=1)


def test_obj_groups_come_through_as_arrays(tmp):
    # A tetrahedron whose faces are in two groups (one named by "o") and one in none: read, remeshed (a pin alone: the round trip) and written.
    (tmp / "groups.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ng base\nf 1 3 2\no side wall\nf 1 2 4\nf 1 4 3\ng\nf 2 3 4\n")
    V, F, A = voxwarp.read_mesh(tmp / "groups.obj", attributes=True)
    assert A["groups"] == ["base", "side wall"] and A["group"].dtype == np.int32 and A["group"].tolist() == [0, 1, 1, -1]
    V2, F2, report, A2 = voxwarp.deform(V, F, {"edits": [{"constraints": [{"pin": [0.2, 0.2, 0.2]}]}]}, resolution=32, attributes=A)
    assert A2["groups"] == A["groups"] and A2["group"].shape == (len(F2),)
    # Each output triangle in the group of the input face its centroid is nearest, away from the tetrahedron's edges.
    clear, nearest = tetrahedron_faces(V2, F2, report["voxel_size"])
    assert (A2["group"][clear] == np.array([0, 1, 1, -1])[nearest[clear]]).all()
    voxwarp.write_mesh(tmp / "out.obj", V2, F2, A2)
    _, F3, A3 = voxwarp.read_mesh(tmp / "out.obj", attributes=True)
    assert A3["groups"] == A2["groups"] and np.array_equal(A3["group"], A2["group"]) and np.array_equal(F3, F2)
    with pytest.raises(voxwarp.InvalidInput, match="\"group\" and \"groups\" go together"):
        voxwarp.write_mesh(tmp / "bad.obj", V2, F2, {"group": A2["group"]})


def test_obj_normals_come_through_as_arrays(tmp):
    # The same tetrahedron flat shaded: each face's corners index its outward normal (OBJ's v//vn).
    n = np.array([[0, 0, -1], [0, -1, 0], [-1, 0, 0], [1, 1, 1]]) / np.array([1, 1, 1, np.sqrt(3)])[:, None]
    (tmp / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n" + "".join(f"vn {a} {b} {c}\n" for a, b, c in n) +
                                  "f 1//1 3//1 2//1\nf 1//2 2//2 4//2\nf 1//3 4//3 3//3\nf 2//4 3//4 4//4\n")
    V, F, A = voxwarp.read_mesh(tmp / "flat.obj", attributes=True)
    assert A["normal"].shape == (4, 3) and A["normal_index"].dtype == np.int32 and A["normal_index"].tolist() == [[i] * 3 for i in range(4)]
    V2, F2, report, A2 = voxwarp.deform(V, F, {"edits": [{"constraints": [{"pin": [0.2, 0.2, 0.2]}]}]}, resolution=32, attributes=A)
    assert A2["normal_index"].shape == F2.shape
    # Away from the edges, each output corner carries the normal of the face it lies on.
    clear, nearest = tetrahedron_faces(V2, F2, report["voxel_size"])
    carried = A2["normal"][A2["normal_index"][clear]]
    assert np.abs(carried - n[nearest[clear]][:, None, :]).max() < 1e-9
    voxwarp.write_mesh(tmp / "out.obj", V2, F2, A2)
    _, F3, A3 = voxwarp.read_mesh(tmp / "out.obj", attributes=True)
    assert np.array_equal(F3, F2) and np.array_equal(A3["normal_index"], A2["normal_index"]) and np.abs(A3["normal"] - A2["normal"]).max() < 1e-12
    with pytest.raises(voxwarp.InvalidInput, match="\"normal\" and \"normal_index\" go together"):
        voxwarp.write_mesh(tmp / "bad.obj", V2, F2, {"normal": A2["normal"]})
