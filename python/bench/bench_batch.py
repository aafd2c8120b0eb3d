"""Throughput of voxwarp.batch on a LocalCluster: 8 bunny ear deforms on 1 and on 2 worker processes (the
cluster started before the clock, outputs in a temporary folder). Prints jobs per second and the ratio.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/bench_batch.py [--resolution 128] [--jobs 8]
"""
import argparse
import os
import tempfile
import time

from distributed import Client, LocalCluster

import voxwarp  # noqa: F401
from voxwarp import batch

def main():
    here = os.path.dirname(os.path.abspath(__file__))
    data = os.path.join(here, "..", "..", "data")
    parser = argparse.ArgumentParser()
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--jobs", type=int, default=8)
    args = parser.parse_args()

    rates = {}
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as folder, LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, Client(cluster) as client:
            threads = max(1, (os.cpu_count() or 1) // workers)
            client.run(batch._prepare_worker, os.path.dirname(os.path.dirname(os.path.abspath(batch.__file__))), threads)
            jobs = [{"mesh": os.path.join(data, "bunny.obj"), "edit": os.path.join(data, "bunny_ear.json"), "output": os.path.join(folder, "out%d.ply" % i),
                     "resolution": args.resolution} for i in range(args.jobs)]
            start = time.perf_counter()
            results = batch.deform_many(jobs, client=client)
            seconds = time.perf_counter() - start
            assert all(r["status"] == "done" for r in results), results
            rates[workers] = args.jobs / seconds
            print("%d bunny deforms at %d on %d worker(s), %d thread(s) each: %.2f s, %.2f jobs/s" % (args.jobs, args.resolution, workers, threads, seconds, rates[workers]))
    print("2 workers / 1 worker: %.2f x" % (rates[2] / rates[1]))


if __name__ == "__main__":  # the workers are spawned processes: they must not rerun this
    main()
