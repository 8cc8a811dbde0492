"""Many releases at once: the runs' energy evaluations gathered into batched kernel calls.

The runs of a study that share a mesh topology (same sheet, same rods' footprints; h, the
moduli, the seed may differ) do the same kind of work at every Newton iteration: assemble a
gradient and a Hessian, evaluate energies along a line search, linearize stresses. Here each
run follows the single-run release of :mod:`undulate.solve.release` unchanged, in its own
thread, but its :class:`~undulate.mechanics.assemble.Assembly` is replaced by a
:class:`BatchMember` whose evaluations wait at a rendezvous: once every live run waits, the
requests are grouped by kind and each kind is evaluated for the runs that asked in one
``vmap``-ed call per element chunk (:class:`~undulate.mechanics.batched.RunBatch`), their rows
filled up with copies to a power of two (a few compiled shapes per kernel).

So the batched path takes the same decisions as the single-run engine (each run keeps its own
step control, curved steps, line searches and linear solver) and ends in the same states;
what it changes is how often the kernels are called: once per kind of request per rendezvous
instead of once per run. That is what a GPU needs (one launch for the whole study's
assembly); the linear algebra stays per run here (the host's sparse direct solver).

    from undulate.solve.batch import release_batch
    results = release_batch([case_a, case_b, case_c])   # SimResult or the run's exception
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..mechanics.assemble import Assembly
from ..mechanics.batched import RunBatch
from ..model import Case
from .release import ProgressFn, SimResult, run_release

__all__ = ["BatchMember", "release_batch"]


class _Request:
    __slots__ = ("kind", "args", "value", "error", "done")

    def __init__(self, kind: str, args: tuple) -> None:
        self.kind, self.args = kind, args
        self.value: Any = None
        self.error: BaseException | None = None
        self.done = False


class _Rendezvous:
    """Where the runs' threads meet: assemblies are registered (the batch is built when all
    have come), requests wait until every live run has one, then all are evaluated."""

    def __init__(self, n_runs: int) -> None:
        self.cv = threading.Condition()
        self.asms: list[Assembly | None] = [None] * n_runs
        self.live = set(range(n_runs))
        self.batch: RunBatch | None = None
        self.error: BaseException | None = None
        self.pending: dict[int, _Request] = {}
        #: rendezvous held and kernel calls made (for the docs' measurements)
        self.rounds = 0
        self.calls = 0

    # ---------------------------------------------------------------- registration
    def register(self, b: int, asm: Assembly) -> BatchMember:
        with self.cv:
            self.asms[b] = asm
            self._maybe_build()
            while self.batch is None and self.error is None:
                self.cv.wait()
            if self.error is not None:
                raise self.error
        return BatchMember(asm, self, b)

    def _maybe_build(self) -> None:
        if (self.batch is not None or all(a is None for a in self.asms)
                or any(self.asms[b] is None for b in self.live)):
            return  # built, nothing to build from (every run failed early), or runs to wait for
        # runs that failed before registering leave no assembly: the batch keeps one row
        # per run index, filled with a registered run's assembly
        first = next(a for a in self.asms if a is not None)
        try:
            self.batch = RunBatch([a if a is not None else first for a in self.asms])
        except ValueError as exc:
            self.error = exc
        self.cv.notify_all()

    def leave(self, b: int) -> None:
        """Run ``b`` is done (or failed): the others no longer wait for it."""
        with self.cv:
            self.live.discard(b)
            self._maybe_build()
            self._maybe_flush()

    # ---------------------------------------------------------------- requests
    def call(self, b: int, kind: str, *args: Any) -> Any:
        req = _Request(kind, args)
        with self.cv:
            self.pending[b] = req
            self._maybe_flush()
            while not req.done:
                self.cv.wait()
        if req.error is not None:
            raise req.error
        return req.value

    def _maybe_flush(self) -> None:
        if not self.pending or self.batch is None or set(self.pending) != self.live:
            return
        pending, self.pending = self.pending, {}
        self.rounds += 1
        for kind in sorted({r.kind for r in pending.values()}):
            reqs = {b: r for b, r in pending.items() if r.kind == kind}
            try:
                values = self._evaluate(kind, reqs)
                for b, r in reqs.items():
                    r.value = values[b]
            except BaseException as exc:  # handed to every run that asked for this kind
                for r in reqs.values():
                    r.error = exc
            self.calls += 1
        for r in pending.values():
            r.done = True
        self.cv.notify_all()

    def _evaluate(self, kind: str, reqs: dict[int, _Request]) -> dict[int, Any]:
        """One batched evaluation of ``kind`` for the runs in ``reqs``: their rows, filled up
        with copies of the first to a power of two (at most the batch size), so that a kernel
        has a few compiled shapes, not one per number of runs asking."""
        batch = self.batch
        assert batch is not None
        runs = sorted(reqs)
        m = min(1 << (len(runs) - 1).bit_length(), batch.batch)
        runs = runs + [runs[0]] * (m - len(runs))
        rows = [reqs[b].args for b in runs]

        def stacked(k: int) -> np.ndarray:
            return np.stack([np.asarray(r[k], dtype=np.float64) for r in rows])

        if kind == "energy":
            values = batch.energy(runs, stacked(0))
        elif kind == "gradient":
            values = batch.gradient(runs, stacked(0))
        elif kind == "gradient_hessian":
            values = batch.gradient_hessian(runs, stacked(0), [r[1] for r in rows])
        elif kind == "stress_linearized":
            values = batch.stress_linearized(runs, stacked(0), stacked(1))
        elif kind == "merit":
            values = batch.merit(runs, stacked(0), stacked(1))
        else:  # pragma: no cover
            raise ValueError(f"batch of runs: unknown request {kind!r}")
        return {b: values[r] for r, b in enumerate(runs[: len(reqs)])}


class BatchMember:
    """One run's view of the batch: an :class:`Assembly` whose energy, gradient, Hessian,
    linearized stresses and merits are evaluated together with the other runs' (everything
    else is the run's own assembly)."""

    def __init__(self, asm: Assembly, rendezvous: _Rendezvous, index: int) -> None:
        self._asm, self._rv, self._b = asm, rendezvous, index

    def __getattr__(self, name: str) -> Any:
        return getattr(self._asm, name)

    def energy(self, x: np.ndarray) -> float:
        return self._rv.call(self._b, "energy", x)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return self._rv.call(self._b, "gradient", x)

    def gradient_hessian(self, x: np.ndarray, stress: dict[int, np.ndarray] | None = None):
        return self._rv.call(self._b, "gradient_hessian", x, stress)

    def stress_linearized(self, x: np.ndarray, dx: np.ndarray) -> dict[int, np.ndarray]:
        return self._rv.call(self._b, "stress_linearized", x, dx)

    def merit(self, x: np.ndarray, dx: np.ndarray) -> tuple[float, float]:
        return self._rv.call(self._b, "merit", x, dx)


def release_batch(cases: Sequence[Case],
                  progress: Callable[[int, float, dict], None] | None = None,
                  stats: dict | None = None) -> list[SimResult | BaseException]:
    """Release every case with the single-run engine, their evaluations batched.

    The cases must share the mesh topology (the same sheet, rods and mesh settings; the rods'
    thickness and moduli, the fabric's moduli and the seed may differ): otherwise every run
    ends with a ValueError naming the first difference. Returns, per case, its
    :class:`SimResult` or the exception that ended it (a ``ConvergenceError`` with step and
    residual). ``progress(b, fraction, record)`` is called from run b's thread. ``stats``,
    when given, receives the number of rendezvous and of batched kernel requests.
    """
    n = len(cases)
    if n == 0:
        return []
    rv = _Rendezvous(n)
    out: list[SimResult | BaseException | None] = [None] * n

    def work(b: int) -> None:
        prog: ProgressFn | None = None
        if progress is not None:
            def prog(frac: float, rec: dict, b: int = b) -> None:
                progress(b, frac, rec)
        try:
            out[b] = run_release(cases[b], prog, assembly=lambda a: rv.register(b, a))
        except BaseException as exc:  # noqa: BLE001 - reported per run
            out[b] = exc
        finally:
            rv.leave(b)

    # daemon threads: an interrupted caller (Ctrl-C in join) can exit without waiting for them
    threads = [threading.Thread(target=work, args=(b,), name=f"undulate-run-{b}", daemon=True)
               for b in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if stats is not None:
        stats.update(rendezvous=rv.rounds, batched_calls=rv.calls)
    return [r if r is not None else RuntimeError("run ended without a result") for r in out]
