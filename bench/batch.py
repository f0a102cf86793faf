"""Batch retargeting (`retarget batch`, retarget/batch/): pairs per second on 1 and 2 Dask
workers, the scheduler's overhead per task, and a projection for a 100-core cluster.

    python bench/batch.py [--characters 3] [--takes 8] [--frames 60] [--deformer ellipsoid]
                          [--outputs gltf npy] [--tasks 400]

A generated batch (`retarget.testing.batch_manifest`: sample-face characters, one as an
exported project; takes of the built-in performance) run with ``--force`` into a fresh
folder each time:

    here       the in-process path (``--workers 0``)
    1 worker   a LocalCluster of 1 single-thread worker process
    2 workers  of 2; the ratio to 1 worker is the scaling on this machine

Each run is timed from the plan to the last result (the cluster is started and warmed
first, apart); each counts the characters' rigs (once per character) and the pairs.

    overhead   a no-op task's cost on the scheduler: --tasks submitted at once and gathered
               (throughput, seconds per task), and one task's round trip alone (latency)

The projection for 100 cores is arithmetic, not a measurement: 100 x the 1-worker pair
rate x the 2-worker efficiency measured here, capped by the scheduler's no-op throughput.
Progress on stderr; figures on stdout. No timed asserts.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from retarget.batch import plan_batch, read_manifest, run_batch  # noqa: E402
from retarget.testing.batch_manifest import write_batch_fixture  # noqa: E402


def _noop(i):
    return i


def _timed_run(manifest, out: Path, **where) -> tuple[float, int]:
    """(seconds, pairs run) of a forced run of the manifest into `out`."""
    plan = plan_batch(manifest, out, force=True)
    start = time.perf_counter()
    report = run_batch(plan, **where)
    seconds = time.perf_counter() - start
    if report.failed:
        raise SystemExit(f"bench batch failed: {report.failed}")
    return seconds, len(report.succeeded)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, default=3)
    parser.add_argument("--takes", type=int, default=8)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--deformer", default="ellipsoid")
    parser.add_argument("--outputs", nargs="+", default=["gltf", "npy"])
    parser.add_argument("--tasks", type=int, default=400)
    args = parser.parse_args()

    from distributed import Client, LocalCluster

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print(f"generating {args.characters} characters x {args.takes} takes of {args.frames} frames ...",
              file=sys.stderr)
        manifest = read_manifest(write_batch_fixture(
            tmp / "in", n_characters=args.characters, n_takes=args.takes, n_frames=args.frames,
            broken=False, deformer=args.deformer, outputs=tuple(args.outputs)))
        n = len(manifest.pairs)
        print(f"batch: {args.characters} characters x {args.takes} takes = {n} pairs, {args.frames} frames "
              f"each, rig {args.deformer}, outputs {', '.join(args.outputs)}; {os.cpu_count()} cores "
              f"(shared with whatever else runs)")
        seconds, done = _timed_run(manifest, tmp / "here", workers=0)
        print(f"  here      {done / seconds:6.2f} pairs/s ({seconds:.2f} s)")
        rates = {}
        for workers in (1, 2):
            with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster, Client(cluster) as client:
                client.wait_for_workers(workers)
                _timed_run(manifest, tmp / f"warm{workers}", client=client)  # imports, caches
                seconds, done = _timed_run(manifest, tmp / f"w{workers}", client=client)
                rates[workers] = done / seconds
                print(f"  {workers} worker{'s' if workers > 1 else ' '} {rates[workers]:6.2f} pairs/s "
                      f"({seconds:.2f} s)")
                if workers == 2:
                    client.gather(client.map(_noop, range(50), pure=False))  # warm
                    start = time.perf_counter()
                    client.gather(client.map(_noop, range(args.tasks), pure=False))
                    per_task = (time.perf_counter() - start) / args.tasks
                    trips = []
                    for i in range(20):
                        start = time.perf_counter()
                        client.submit(_noop, i, pure=False).result()
                        trips.append(time.perf_counter() - start)
                    trips.sort()
                    latency = trips[len(trips) // 2]
        ratio = rates[2] / rates[1]
        print(f"  scaling   2 workers / 1 worker = {ratio:.2f} (2.00 is linear; {100 * ratio / 2:.0f} % "
              "efficiency)")
        print(f"  overhead  {1e3 * per_task:.2f} ms per no-op task ({args.tasks} at once: "
              f"{1 / per_task:.0f} tasks/s); one task's round trip {1e3 * latency:.2f} ms; against "
              f"{1e3 / rates[1]:.0f} ms per pair on 1 worker")
        efficiency = min(1.0, ratio / 2)
        projected = min(100 * rates[1] * efficiency, 1 / per_task)
        print(f"  projection (not measured): 100 cores at the 1-worker rate x {efficiency:.2f} efficiency "
              f"= {100 * rates[1] * efficiency:.0f} pairs/s; the scheduler's no-op throughput caps it at "
              f"{1 / per_task:.0f} tasks/s -> about {projected:.0f} pairs/s")


if __name__ == "__main__":
    main()
