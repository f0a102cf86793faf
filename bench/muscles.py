"""Muscle IK (issue 15, Woodward §7) on one CPU core: speed, iterations and accuracy of the
solvers on a synthetic performance.

    python bench/muscles.py [--frames 300] [--repeats 3] [--noise 0.05] [--lost 0.02]
                            [--atol 0.001] [--model real|standin] [--seed 0]

The face: the muscles placed on the built-in sample face (`place_muscles`, 68 iBUG points
marked, 22 DOFs, cm; --model real), or the tests' stand-in model (21 smooth fields and a
jaw, tests/unit/test_muscle_ik.py; --model standin).

The performance: --frames frames at 30 fps of smooth random contractions (each DOF a
half-wave rectified sine of its own frequency, 0.1-0.5 Hz, and amplitude, so muscles rest at
0 for long stretches and the lower bounds are active) with the jaw opening and closing.
Targets are the marked vertices displaced by the true contractions, exact ("clean") or with
tracker-like noise: Gaussian, --noise cm per coordinate, and a --lost share of the points
lost (NaN rows) in each frame ("noisy"). Every solver stops at its default relative
tolerance or at --atol cm RMS residual (10 um by default: exact targets would otherwise be
chased into rounding noise, which no tracker warrants).

Sections (functions, so later benches can add theirs):
    model cost   one `displacements` and one `jacobian` of the restricted model: the floor
                 under every iteration
    solvers      for each solver (`MuscleIK`, warm-started frame to frame), clean and noisy:
                 ms a frame (median frame, and p95, of the median run over --repeats;
                 wall clock, and the thread's CPU time, which a loaded machine inflates
                 less),
                 iterations a frame (mean, max), contraction error (mean |c - truth| as a
                 share of each DOF's range), residual (RMS marked vertex to its target, cm,
                 IKResult.residual) and truth error (RMS marked vertex to its noise-free
                 position, cm; under noise, over the input noise's RMS: below 1 means the
                 muscles absorbed noise)
    built-in performance  (--model real) the sample face's demo performance (its own
                 expression shapes, which muscles only approximate) at the 68 marked
                 vertices: ms a frame, iterations, residual (cm, and as a share of the
                 marked motion's RMS)

The machine's load is printed first: the figures move with it.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.stream import machine  # noqa: E402
from retarget.muscles import place_muscles  # noqa: E402
from retarget.muscles.ik import MuscleIK  # noqa: E402
from retarget.sample_face import demo_weights, sample_face  # noqa: E402

# (label, MuscleIK keyword arguments): the two solvers of the issue and a variant of each.
SOLVERS = (
    ("dls", dict(method="dls")),
    ("dls, rest J", dict(method="dls", jacobian="rest")),
    ("transpose", dict(method="transpose")),
    ("transpose, plain", dict(method="transpose", precondition=False)),
)


def face_model(kind: str):
    """(whole model, (68,) marked vertex ids, label) for --model `kind`."""
    if kind == "real":
        face = sample_face()
        ids = face.landmarks68
        model = place_muscles(face.vertices, face.faces, face.vertices[ids], "ibug68")
        return model, ids, "muscles placed on the built-in face (68 iBUG points)"
    sys.path.insert(0, str(ROOT / "tests" / "unit"))
    from test_muscle_ik import StandInFace

    return StandInFace.build(), np.arange(0, 400, 400 // 68)[:68], "tests' stand-in model (68 points)"


def trajectory(limits: np.ndarray, n_frames: int, rng: np.random.Generator) -> np.ndarray:
    """(F, D) smooth contractions at 30 fps within `limits` (D, 2): half-wave rectified
    sines, 0.1-0.5 Hz, amplitude 30-90 % of the range; the jaw (last DOF) likewise."""
    low, high = limits.T
    t = np.arange(n_frames)[:, None] / 30.0
    f = rng.uniform(0.1, 0.5, size=len(low))
    phase = rng.uniform(0.0, 2 * np.pi, size=len(low))
    amplitude = rng.uniform(0.3, 0.9, size=len(low))
    wave = np.maximum(np.sin(2 * np.pi * f * t + phase), 0.0)
    return np.clip(low + (high - low) * amplitude * wave, low, high)


def noisy(clean: np.ndarray, sigma: float, lost: float, rng: np.random.Generator) -> np.ndarray:
    """(F, K, 3) `clean` plus Gaussian noise (sigma per coordinate) with a `lost` share of
    rows NaN (points the tracker lost)."""
    out = clean + rng.normal(0.0, sigma, size=clean.shape)
    out[rng.random(clean.shape[:2]) < lost] = np.nan
    return out


def model_cost(model, ids, repeats: int = 200) -> None:
    """Section: one displacements() and one jacobian() of the model restricted to `ids`."""
    sub = model.restricted(ids)
    c = 0.3 * model.limits[:, 1]
    for name, fn in (("displacements", sub.displacements), ("jacobian", sub.jacobian)):
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(c)
            times.append(time.perf_counter() - t0)
        print(f"  {name:<14} {1e3 * statistics.median(times):7.3f} ms  (K = {len(ids)}, D = {model.n_dof})")


def run_sequence(model, ids, options: dict, targets: np.ndarray, truth: np.ndarray) -> dict:
    """One pass of a warm-started `MuscleIK` over `targets` (F, K, 3) displacements;
    `truth` (F, D) the contractions that made them. Figures of the pass."""
    ik = MuscleIK(model, ids, **options)
    sub = ik.model_
    span = np.where(np.ptp(model.limits, axis=1) > 0, np.ptp(model.limits, axis=1), 1.0)
    times, cpu, iterations, residuals, c_err, v_err = [], [], [], [], [], []
    for target, c_true in zip(targets, truth):
        t0, u0 = time.perf_counter(), time.thread_time()
        c = ik.push(target)
        times.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - u0)
        iterations.append(ik.result_.iterations)
        residuals.append(ik.result_.residual)
        c_err.append(np.mean(np.abs(c - c_true) / span))
        miss = sub.displacements(c) - sub.displacements(c_true)
        v_err.append(np.sqrt(np.mean(np.sum(miss ** 2, axis=1))))
    return dict(ms=1e3 * np.median(times), p95=1e3 * np.percentile(times, 95), cpu=1e3 * np.median(cpu),
                iterations=np.mean(iterations), max_iterations=int(np.max(iterations)),
                c_err=np.mean(c_err), residual=np.nanmean(residuals), v_err=np.mean(v_err))


def solvers(model, ids, frames: int, repeats: int, sigma: float, lost: float, atol: float, seed: int) -> None:
    """Section: every solver of SOLVERS on the clean and the noisy performance."""
    rng = np.random.default_rng(seed)
    truth = trajectory(np.asarray(model.limits), frames, rng)
    sub = model.restricted(ids)
    clean = np.stack([sub.displacements(c) for c in truth])
    conditions = (("clean", clean), (f"noisy ({sigma:g} cm, {lost:.0%} lost)", noisy(clean, sigma, lost, rng)))
    noise_rms = sigma * np.sqrt(3.0)
    print(f"  {frames} frames; marked motion RMS {np.sqrt(np.mean(np.sum(clean ** 2, axis=2))):.3f} cm, "
          f"largest {np.linalg.norm(clean, axis=2).max():.3f} cm; input noise RMS {noise_rms:.3f} cm a point")
    print(f"  {'solver':<18} {'targets':<26} {'ms/frame':>8} {'p95':>7} {'cpu ms':>7} {'iter':>6} {'max':>5} "
          f"{'c err':>7} {'residual':>9} {'truth err':>9}")
    for label, options in SOLVERS:
        for name, targets in conditions:
            runs = [run_sequence(model, ids, dict(options, atol=atol), targets, truth) for _ in range(repeats)]
            r = sorted(runs, key=lambda run: run["ms"])[len(runs) // 2]     # the median run
            ratio = f" ({r['v_err'] / noise_rms:.2f}x)" if targets is not clean else ""
            print(f"  {label:<18} {name:<26} {r['ms']:8.3f} {r['p95']:7.3f} {r['cpu']:7.3f} {r['iterations']:6.1f} "
                  f"{r['max_iterations']:5d} {100 * r['c_err']:6.2f}% {r['residual']:9.5f} "
                  f"{r['v_err']:9.5f}{ratio}")


def builtin_performance(model, ids, frames: int, repeats: int, atol: float) -> None:
    """Section: the built-in demo performance (the sample face's own expression shapes,
    `demo_weights`, not made by muscles) at the 68 marked vertices: targets the muscles can
    only approximate, as real tracking gives. Real model only (the same mesh and ids)."""
    face = sample_face()
    targets = np.einsum("fe,evk->fvk", demo_weights(frames), face.expressions[:, ids])
    motion = np.sqrt(np.mean(np.sum(targets ** 2, axis=2)))
    print(f"  {frames} frames; marked motion RMS {motion:.3f} cm")
    print(f"  {'solver':<18} {'ms/frame':>8} {'p95':>7} {'iter':>6} {'max':>5} {'residual':>9} {'of motion':>9}")
    for label, options in SOLVERS:
        runs = []
        for _ in range(repeats):
            ik = MuscleIK(model, ids, **options, atol=atol)
            times, iterations, residuals = [], [], []
            for target in targets:
                t0 = time.perf_counter()
                ik.push(target)
                times.append(time.perf_counter() - t0)
                iterations.append(ik.result_.iterations)
                residuals.append(ik.result_.residual)
            runs.append((1e3 * np.median(times), 1e3 * np.percentile(times, 95), np.mean(iterations),
                         int(np.max(iterations)), np.mean(residuals)))
        ms, p95, it, top, res = sorted(runs)[len(runs) // 2]
        print(f"  {label:<18} {ms:8.3f} {p95:7.3f} {it:6.1f} {top:5d} {res:9.5f} {res / motion:8.0%}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--noise", type=float, default=0.05, help="tracker noise, cm per coordinate")
    parser.add_argument("--lost", type=float, default=0.02, help="share of points lost a frame")
    parser.add_argument("--model", choices=("real", "standin"), default="real")
    parser.add_argument("--atol", type=float, default=1e-3,
                        help="stop at this RMS residual, cm (clean targets converge forever otherwise)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(machine())
    model, ids, label = face_model(args.model)
    print(f"model: {label}, D = {model.n_dof}")
    print("model cost")
    model_cost(model, ids)
    print("solvers (MuscleIK, warm-started)")
    solvers(model, ids, args.frames, args.repeats, args.noise, args.lost, args.atol, args.seed)
    if args.model == "real":
        print("built-in performance (MuscleIK, warm-started)")
        builtin_performance(model, ids, args.frames, args.repeats, args.atol)


if __name__ == "__main__":
    main()
