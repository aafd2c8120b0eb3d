"""Many deforms at once on a Dask cluster (distributed): voxwarp.batch.deform_many, or on the command line

    python3 -m voxwarp.batch JOBS.json [--scheduler ADDRESS] [--workers N] [--resolution N]

A job is a dict: {"mesh": path, "edit": path or edit dict, "output": path, and optionally "resolution",
"voxel_size", "mode", "preview", "max_steps", "faces", "mesher" (deform's keywords)}. JOBS.json holds a list of jobs or
{"jobs": [...]}; relative paths are taken from the file's folder.

Each job writes its output mesh and then OUTPUT.report.json (the deform report, plus the output's size), both
written to a temporary file and renamed, so a job either left both or nothing usable. A rerun skips the jobs
whose report is there and whose output has the size the report recorded. A job that fails (a malformed mesh, a
wrong edit file) is reported with its error kind and message while the others finish.

Without a client, a LocalCluster of one process per worker (one thread each: voxwarp parallelises inside a
job) runs on this machine. Any scheduler address runs the jobs on that cluster; its workers must be able to
import voxwarp and to read and write the jobs' paths.
"""

import argparse
import json
import os
import sys
import tempfile
import time


def report_path(output):
    """Where the report of the job writing `output` goes."""
    return os.fspath(output) + ".report.json"


def _complete(job):
    try:
        with open(report_path(job["output"]), encoding="utf-8") as f:
            report = json.load(f)
        return os.path.getsize(job["output"]) == report.get("output_bytes")
    except (OSError, ValueError):
        return False


def _write_atomically(path, text):
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".voxwarp-", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


_DEFORM_KEYWORDS = ("resolution", "voxel_size", "mode", "preview", "max_steps", "faces", "mesher")


def run_job(job):
    """Run one job here (a worker calls this). Returns {"output", "status": "done", "seconds", "report", "worker" (its
    process id)} or
    {"output", "status": "failed", "error": kind, "message"}; never raises for a job's own failure."""
    import voxwarp

    start = time.perf_counter()
    try:
        unknown = set(job) - {"mesh", "edit", "output", *_DEFORM_KEYWORDS}
        if unknown:
            raise voxwarp.InvalidInput("job: unknown field(s) %s; expected mesh, edit, output, %s" % (", ".join(sorted(unknown)), ", ".join(_DEFORM_KEYWORDS)))
        for field in ("mesh", "edit", "output"):
            if field not in job:
                raise voxwarp.InvalidInput("job: missing field \"%s\"" % field)
        V, F, attributes = voxwarp.read_mesh(job["mesh"], attributes=True)
        options = {k: job[k] for k in _DEFORM_KEYWORDS if k in job}
        V2, F2, report, attributes = voxwarp.deform(V, F, job["edit"], attributes=attributes, **options)
        voxwarp.write_mesh(job["output"], V2, F2, attributes)  # texture coordinates, colours and materials carried
        report.update({"input": os.fspath(job["mesh"]), "output": os.fspath(job["output"]), "output_bytes": os.path.getsize(job["output"])})
        if not isinstance(job["edit"], dict):
            report["edits_file"] = os.fspath(job["edit"])
        _write_atomically(report_path(job["output"]), json.dumps(report, indent=2) + "\n")
        return {"output": os.fspath(job["output"]), "status": "done", "seconds": time.perf_counter() - start, "report": report, "worker": os.getpid()}
    except voxwarp.Error as e:
        return {"output": os.fspath(job.get("output", "")), "status": "failed", "error": type(e).__name__, "message": str(e)}
    except Exception as e:  # a worker must report, not die: anything else is an internal error of that job
        return {"output": os.fspath(job.get("output", "")), "status": "failed", "error": type(e).__name__, "message": str(e)}


def _prepare_worker(folder, threads):
    if folder not in sys.path:
        sys.path.insert(0, folder)
    import voxwarp

    voxwarp.set_threads(threads)


def deform_many(jobs, client=None, workers=None, progress=None, skip_complete=True):
    """Run deform jobs on a Dask cluster; returns one result dict per job, in the jobs' order (see run_job; a
    skipped job has status "skipped").

    client: a distributed.Client, a scheduler address, or None for a LocalCluster of `workers` processes
            (default: the machine's cores) with one thread each.
    progress: called as progress(done, total) after each job, or True for a bar on stderr.
    """
    from distributed import Client, LocalCluster, as_completed

    jobs = [dict(j) for j in jobs]
    results = [None] * len(jobs)
    pending = []
    for i, job in enumerate(jobs):
        if skip_complete and "output" in job and _complete(job):
            results[i] = {"output": os.fspath(job["output"]), "status": "skipped"}
        else:
            pending.append(i)
    show = _bar if progress is True else progress
    total, done = len(jobs), len(jobs) - len(pending)
    if show:
        show(done, total)
    if not pending:
        return results

    owned = []
    threads = 0  # a remote cluster's workers keep their machines' cores
    if client is None:
        workers = workers or os.cpu_count() or 1
        threads = max(1, (os.cpu_count() or 1) // workers)  # the machine's cores shared among the local workers
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
        owned = [client, cluster]
    elif isinstance(client, str):
        client = Client(client)
        owned = [client]
    try:
        # Workers import voxwarp from where this process found it.
        package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        client.run(_prepare_worker, package_root, threads)
        futures = {client.submit(run_job, jobs[i], pure=False): i for i in pending}
        for future in as_completed(futures):
            i = futures[future]
            try:
                results[i] = future.result()
            except Exception as e:  # the worker itself was lost
                results[i] = {"output": os.fspath(jobs[i].get("output", "")), "status": "failed", "error": type(e).__name__, "message": str(e)}
            done += 1
            if show:
                show(done, total)
    finally:
        for thing in owned:
            thing.close()
    return results


def _bar(done, total, width=30):
    filled = width * done // max(total, 1)
    sys.stderr.write("\rvoxwarp batch [%s%s] %d/%d" % ("#" * filled, "." * (width - filled), done, total))
    if done == total:
        sys.stderr.write("\n")
    sys.stderr.flush()


def load_jobs(path):
    """Jobs from a JOBS.json file: a list, or {"jobs": [...]}; relative paths are taken from the file's folder."""
    with open(path, encoding="utf-8") as f:
        data = json.load(f)
    jobs = data["jobs"] if isinstance(data, dict) and "jobs" in data else data
    if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        raise ValueError("%s: expected a list of jobs or {\"jobs\": [...]}" % path)
    base = os.path.dirname(os.path.abspath(path))
    for job in jobs:
        for field in ("mesh", "edit", "output"):
            if isinstance(job.get(field), str) and not os.path.isabs(job[field]):
                job[field] = os.path.join(base, job[field])
    return jobs


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python3 -m voxwarp.batch", description="Run many voxwarp deform jobs on a Dask cluster.")
    parser.add_argument("jobs", help="JOBS.json: a list of {mesh, edit, output[, resolution, ...]}")
    parser.add_argument("--scheduler", help="Dask scheduler address (default: a LocalCluster on this machine)")
    parser.add_argument("--workers", type=int, help="LocalCluster worker processes (default: the machine's cores)")
    parser.add_argument("--resolution", type=int, help="resolution for jobs that do not set one")
    parser.add_argument("--no-skip", action="store_true", help="rerun jobs whose output is complete")
    args = parser.parse_args(argv)
    try:
        jobs = load_jobs(args.jobs)
    except (OSError, ValueError, KeyError) as e:
        print("voxwarp batch: error: %s" % e, file=sys.stderr)
        return 2
    if args.resolution:
        for job in jobs:
            job.setdefault("resolution", args.resolution)
    start = time.perf_counter()
    results = deform_many(jobs, client=args.scheduler, workers=args.workers, progress=True, skip_complete=not args.no_skip)
    failed = [r for r in results if r["status"] == "failed"]
    for r in failed:
        print("voxwarp batch: %s: %s: %s" % (r["output"], r["error"], r["message"]), file=sys.stderr)
    counts = {s: sum(r["status"] == s for r in results) for s in ("done", "skipped", "failed")}
    print("voxwarp batch: %d done, %d skipped, %d failed in %.1f s" % (counts["done"], counts["skipped"], counts["failed"], time.perf_counter() - start), file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    # Through the package, so that the workers unpickle voxwarp.batch.run_job by name, not this script's copy.
    from voxwarp.batch import main as _main

    sys.exit(_main())
