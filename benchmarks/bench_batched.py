"""Batched evaluation (mechanics/batched.py) against one run at a time, on the demo's mesh.

    python benchmarks/bench_batched.py            # B = 1, 4, 16 runs (h from 0.2 to 0.5)
    python benchmarks/bench_batched.py --batch 8

For each batch size B: the time of one ``BatchedAssembly.evaluate`` (energy, gradient and
Hessian values of all B runs; compiled once, then the best of 3) against B calls of the
single-run ``Assembly.gradient_hessian`` plus ``energy`` (best of 3), at the printed state
with a small out-of-plane perturbation; with the yardstick (``../shared/yardstick.py``)
measured before and after. On a CPU this says what batching the kernels costs or saves; on a
GPU (``pip install undulate[gpu]`` style JAX) the same script measures the device.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def yardstick() -> float | None:
    script = Path(__file__).resolve().parents[2] / "shared" / "yardstick.py"
    if not script.is_file():
        return None
    t = time.perf_counter()
    subprocess.run([sys.executable, str(script)], check=True, capture_output=True)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, nargs="*", default=[1, 4, 16])
    args = ap.parse_args()
    import jax

    from undulate.mechanics.assemble import Assembly
    from undulate.mechanics.batched import BatchedAssembly
    from undulate.model import case_from_dict
    from undulate.solve.newton import NewtonOptions
    from undulate.solve.release import _clamped, prepare, prestretch
    from undulate.solve.terms import TermState, groups

    ys0 = yardstick()
    print(f"JAX devices: {jax.devices()}")
    base = prepare(case_from_dict({}))
    x0, _ = prestretch(base, NewtonOptions(force_scale=base.force_scale))
    fixed = np.zeros((base.mesh.n_nodes, 3), bool)
    fixed[_clamped(base)] = True
    rng = np.random.default_rng(0)
    for B in args.batch:
        hs = np.linspace(0.2, 0.5, B)
        asms = []
        for h in hs:
            sim = prepare(case_from_dict({"rods": {"h": float(h)}}))
            asms.append(Assembly(sim.mesh.n_nodes, sim.fabric + groups(
                sim, ("print",), TermState(x0)), fixed))
        X = np.stack([x0 + 1e-2 * rng.standard_normal(x0.shape) * ~fixed for _ in hs])
        batch = BatchedAssembly(asms)
        t = time.perf_counter()
        batch.evaluate(X)
        first = time.perf_counter() - t
        tb = min(_timed(batch.evaluate, X) for _ in range(3))
        ts = min(_timed(_one_at_a_time, asms, X) for _ in range(3))
        print(f"B = {B:3d}: batched {tb:7.3f} s ({tb / B * 1e3:6.1f} ms per run; first call "
              f"with compilation {first:.1f} s), one at a time {ts:7.3f} s "
              f"({ts / B * 1e3:6.1f} ms per run), {asms[0].n_free} unknowns", flush=True)
    ys1 = yardstick()
    if ys0 and ys1:
        print(f"yardstick {ys0:.2f} s before, {ys1:.2f} s after")


def _one_at_a_time(asms, X) -> None:
    for a, x in zip(asms, X, strict=True):
        a.gradient_hessian(x)
        a.energy(x)


def _timed(fn, *args) -> float:
    t = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t


if __name__ == "__main__":
    main()
