# Batch runs on Dask: 8 jobs on a 2-worker LocalCluster, one of them with a malformed mesh; reruns skip what is done.
import json
import os
import subprocess
import sys

import voxwarp
from conftest import data
from voxwarp import batch  # Dask's distributed: the README's commands install it; without it this module fails


def jobs_in(folder, count=8, bad=3):
    broken = folder / "broken.obj"
    broken.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    jobs = []
    for i in range(count):
        jobs.append({"mesh": str(broken) if i == bad else data("bunny.obj"), "edit": data("bunny_ear.json"), "output": str(folder / ("out%d.ply" % i)),
                     "resolution": 32 + 8 * i})
    return jobs


def test_eight_jobs_on_two_workers_one_failing(tmp_path):
    jobs = jobs_in(tmp_path)
    seen = []
    results = batch.deform_many(jobs, workers=2, progress=lambda done, total: seen.append((done, total)))
    assert [r["status"] for r in results] == ["done"] * 3 + ["failed"] + ["done"] * 4
    failed = results[3]
    assert failed["error"] == "InvalidInput" and "broken.obj" in failed["message"] and "refers to vertex 9" in failed["message"]
    assert not os.path.exists(jobs[3]["output"]) and not os.path.exists(batch.report_path(jobs[3]["output"]))
    for job, result in zip(jobs, results):
        if result["status"] != "done":
            continue
        report = json.loads(open(batch.report_path(job["output"])).read())
        assert report["output_bytes"] == os.path.getsize(job["output"])
        V, F = voxwarp.read_mesh(job["output"])
        assert len(F) == report["output_faces"]
    assert seen[-1] == (8, 8)
    # Both workers ran jobs, and what they wrote is what a direct deform writes.
    assert len({r["worker"] for r in results if r["status"] == "done"}) == 2, results
    for i in (0, 7):
        V, F = voxwarp.read_mesh(jobs[i]["mesh"])
        V2, F2, _ = voxwarp.deform(V, F, jobs[i]["edit"], resolution=jobs[i]["resolution"])
        voxwarp.write_mesh(tmp_path / "direct.ply", V2, F2)
        assert (tmp_path / "direct.ply").read_bytes() == open(jobs[i]["output"], "rb").read(), i
    # No temporary files left behind.
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]
    os.remove(tmp_path / "direct.ply")

    # A rerun skips the complete jobs and retries the failed one.
    again = batch.deform_many(jobs, workers=2)
    assert [r["status"] for r in again] == ["skipped"] * 3 + ["failed"] + ["skipped"] * 4
    # An output whose size no longer matches its report is redone.
    with open(jobs[0]["output"], "ab") as f:
        f.write(b"truncated or touched")
    third = batch.deform_many(jobs[:1], workers=1)
    assert third[0]["status"] == "done"


def test_command_line_entry(tmp_path):
    jobs = jobs_in(tmp_path, count=3, bad=1)
    for job in jobs:  # relative paths resolve against the jobs file's folder
        job["output"] = os.path.basename(job["output"])
    (tmp_path / "jobs.json").write_text(json.dumps({"jobs": jobs}))
    env = dict(os.environ)
    r = subprocess.run([sys.executable, "-m", "voxwarp.batch", str(tmp_path / "jobs.json"), "--workers", "2"], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 1, r.stderr  # one job failed
    assert "2 done, 0 skipped, 1 failed" in r.stderr
    assert "broken.obj" in r.stderr
    assert (tmp_path / "out0.ply").exists() and (tmp_path / "out2.ply").exists()
    bad = subprocess.run([sys.executable, "-m", "voxwarp.batch", str(tmp_path / "missing.json")], capture_output=True, text=True, env=env)
    assert bad.returncode == 2 and "missing.json" in bad.stderr
