"""``retarget batch``: many characters x many takes from a manifest, on a Dask cluster or
in this process (`retarget.batch`)."""

from __future__ import annotations

import argparse

from retarget.batch import plan_batch, read_manifest, run_batch
from retarget.batch.bundle import unpacked_bundle

__all__ = ["add_batch"]


def _workers(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {value}")
    return value


def add_batch(commands, parents) -> None:
    p = commands.add_parser(
        "batch", parents=parents, help="retarget every take of a manifest onto every character",
        description="Read a manifest (YAML or JSON: characters, takes, outputs) and make each "
        "pair's outputs into DIR/<character>/<take>/, on a Dask LocalCluster sized to the machine "
        "(default), the scheduler given, or in this process. A rerun skips the pairs done "
        "(DIR/.retarget-batch.json) and redoes the changed ones and those that failed for a "
        "passing reason. Exit status 1 when a pair failed, 2 for a bad manifest.")
    p.add_argument("manifest", metavar="MANIFEST", help="the manifest (.yaml, .yml or .json), or a batch "
                   ".zip the web app exported (unpacked into DIR/.inputs/)")
    p.add_argument("--out", required=True, metavar="DIR", help="the output root (created if missing)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="a Dask scheduler to run on (default: a LocalCluster, or Dask's "
                       "configured scheduler-address)")
    where.add_argument("--workers", type=_workers, metavar="N",
                       help="local worker processes (default: one per core); 0 runs in this process")
    where.add_argument("--no-dask", dest="workers", action="store_const", const=0,
                       help="run in this process (same as --workers 0)")
    p.add_argument("--force", action="store_true", help="redo every pair, done or not")
    p.add_argument("--retry-failed", action="store_true",
                   help="also redo the pairs that failed on inputs that have not changed since")
    p.set_defaults(run=_batch)


def _batch(args) -> int:
    path = args.manifest
    if str(path).lower().endswith(".zip"):  # the web app's export: unpacked beside the outputs
        path = unpacked_bundle(path, args.out)
    manifest = read_manifest(path)
    plan = plan_batch(manifest, args.out, force=args.force, retry_failed=args.retry_failed)
    if not args.quiet:
        print(f"{len(manifest.pairs)} pairs ({len(manifest.characters)} characters x "
              f"{len(manifest.takes)} takes; outputs {', '.join(manifest.outputs)}): "
              f"{len(plan.jobs)} to run, {len(plan.skipped)} done already, {len(plan.failed_before)} "
              f"failed before on the same inputs -> {args.out}")
    report = run_batch(plan, scheduler=args.scheduler, workers=args.workers, quiet=args.quiet)
    print(report.summary())
    return 1 if report.failed or report.failed_before else 0
