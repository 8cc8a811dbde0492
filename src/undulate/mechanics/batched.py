"""Many runs that share one mesh, evaluated in one call: energy, gradient and Hessian values.

The runs of a study that differ only in element parameters (the rods' thickness h, the
moduli E_B and E, ...) share the mesh, the element node lists, the clamped nodes and so the
sparsity pattern of the Hessian. :class:`BatchedAssembly` stacks their parameters along a
leading run axis and evaluates every run with one jitted, ``vmap``-ed function: the element
energies with plain autodiff, the scatter to nodes and to the Hessian's entries with
``jax.ops.segment_sum`` inside the traced function (no host loop per group or per run). The
Hessian comes back as the values of the upper triangle in the CSC pattern of the first run's
:class:`~undulate.mechanics.assemble.Assembly`, one row per run: what a batched
factorization takes.

This is the evaluation half of a batched Newton (issue "GPU: many runs of a study at once");
the single-run :class:`~undulate.mechanics.assemble.Assembly` stays the reference, and the
tests check the two against each other.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .assemble import Assembly
from .compiled import CachedJit
from .forms import _disk_label, gathered_kernels

__all__ = ["BatchedAssembly", "RunBatch", "check_same_topology"]


def check_same_topology(assemblies: Sequence[Assembly]) -> Assembly:
    """The first of ``assemblies`` once all have its nodes, clamps and element groups (same
    names, energy functions and node lists; parameters may differ); ValueError otherwise."""
    if not assemblies:
        raise ValueError("batch of runs: no runs given")
    ref = assemblies[0]
    for k, a in enumerate(assemblies[1:], start=1):
        if a.n_nodes != ref.n_nodes or not np.array_equal(a.fixed, ref.fixed):
            raise ValueError(f"batch of runs: run {k} has other nodes or clamps")
        if [(g.name, g.fn) for g in a.groups] != [(g.name, g.fn) for g in ref.groups]:
            raise ValueError(f"batch of runs: run {k} has other element groups")
        for g, h in zip(a.groups, ref.groups, strict=True):
            if not np.array_equal(g.nodes, h.nodes):
                raise ValueError(f"batch of runs: run {k}, group {g.name}: other nodes")
    return ref


class BatchedAssembly:
    """Energy, free gradient and upper Hessian values of ``B`` runs with one topology.

    ``assemblies``: one :class:`Assembly` per run, with the same nodes, fixed mask and
    element groups (same names, energy functions and node lists); only the groups'
    parameters may differ. Evaluate at ``X`` of shape (B, n_nodes, 3).
    """

    def __init__(self, assemblies: Sequence[Assembly]) -> None:
        ref = check_same_topology(assemblies)
        self.ref = ref
        self.batch = len(assemblies)
        self.n_free = ref.n_free
        self.nnz = ref.nnz
        self._fns = [g.fn for g in ref.groups]
        self._nodes = [jnp.asarray(g.nodes) for g in ref.groups]
        self._params = [
            tuple(jnp.asarray(np.stack([a.groups[i].params[j] for a in assemblies]))
                  for j in range(len(g.params)))
            for i, g in enumerate(ref.groups)
        ]
        # where each element Hessian entry goes among the nnz upper-triangle values (the maps
        # of the reference assembly: kept entries in element order, then their position)
        self._hkeep, self._hdest = [], []
        start = 0
        for keep in ref._keep:
            n_kept = int(np.count_nonzero(keep))
            self._hkeep.append(jnp.asarray(np.nonzero(keep)[0]))
            self._hdest.append(jnp.asarray(ref._scatter[start : start + n_kept]))
            start += n_kept
        self._free = jnp.asarray(ref.free_dofs)
        self._eval = jax.jit(jax.vmap(self._one, in_axes=(0, 0)))

    def _one(self, x: jnp.ndarray, params: list[tuple[jnp.ndarray, ...]]
             ) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
        n = x.shape[0]
        energy = 0.0
        grad = jnp.zeros((n, 3))
        hvals = jnp.zeros(self.nnz)
        for fn, nodes, p, keep, dest in zip(self._fns, self._nodes, params, self._hkeep,
                                            self._hdest, strict=True):
            xl = x[nodes]  # (n_el, k, 3)
            energy = energy + jnp.sum(jax.vmap(fn)(xl, *p))
            ge = jax.vmap(jax.grad(fn))(xl, *p)  # (n_el, k, 3)
            grad = grad + jax.ops.segment_sum(ge.reshape(-1, 3), nodes.ravel(),
                                              num_segments=n)
            he = jax.vmap(jax.hessian(fn))(xl, *p)  # (n_el, k, 3, k, 3): dof order 3 node + c
            hvals = hvals + jax.ops.segment_sum(he.ravel()[keep], dest, num_segments=self.nnz)
        return energy, grad.ravel()[self._free], hvals

    def evaluate(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(energies (B,), free gradients (B, n_free), upper Hessian values (B, nnz))."""
        X = np.asarray(X, dtype=np.float64)
        if X.shape != (self.batch, self.ref.n_nodes, 3):
            raise ValueError(f"BatchedAssembly: X must be {(self.batch, self.ref.n_nodes, 3)};"
                             f" got {X.shape}")
        e, g, h = self._eval(jnp.asarray(X), self._params)
        return np.asarray(e), np.asarray(g), np.asarray(h)

    def hessian(self, values: np.ndarray) -> sp.csc_matrix:
        """One run's upper-triangle Hessian (CSC) from its row of :meth:`evaluate`'s values."""
        return sp.csc_matrix((np.asarray(values, dtype=np.float64), self.ref._indices,
                              self.ref._indptr), shape=(self.n_free, self.n_free))


_RUN_KERNELS: dict[tuple, Callable] = {}


class RunBatch:
    """The element kernels of ``B`` runs with one topology, each kernel called once for many of
    them: the evaluations of :class:`~undulate.mechanics.assemble.Assembly`, batched.

    Where :class:`BatchedAssembly` differentiates the whole energy itself and scatters on the
    device, this class maps the single-run kernels (:func:`gathered_kernels`: the strain forms'
    mixed Hessians, carried stresses, merits) over a leading run axis with ``jax.vmap``, chunk
    by chunk as the runs' own groups are cut, and finishes each run on the host with its own
    :class:`Assembly` (scatter, sums in group order). So every run gets the numbers its own
    assembly would compute, and a batched Newton (:mod:`undulate.solve.batch`) follows the
    single-run solver step by step.

    Every method takes ``runs``, the indices of the runs to evaluate (one row each; an index
    may repeat, to fill a row), and their inputs stacked along the first axis; it returns one
    result per row. Each distinct number of rows is one more compiled program per kernel: the
    caller keeps to a few (:mod:`undulate.solve.batch` uses powers of two).
    """

    def __init__(self, assemblies: Sequence[Assembly]) -> None:
        self.ref = check_same_topology(assemblies)
        self.asms = list(assemblies)
        self.batch = len(self.asms)
        for i, g in enumerate(self.ref.groups):
            if [a.groups[i]._sizes for a in self.asms].count(g._sizes) != self.batch:
                raise ValueError(f"batch of runs: group {g.name} is cut into other chunks")
        # per group, per chunk: the shared nodes and the runs' parameters stacked (B, m, ...)
        self._chunks = [
            [(nodes, tuple(jnp.stack([a.groups[i]._chunks[j][1][p] for a in self.asms])
                           for p in range(len(params))))
             for j, (nodes, params) in enumerate(g._chunks)]
            for i, g in enumerate(self.ref.groups)
        ]

    @staticmethod
    def _kernel(fn: Callable, name: str, n_args: int) -> Callable:
        key = (fn, name, n_args)
        if key not in _RUN_KERNELS:  # shared by all batches (jit keeps one program per shape)
            k = jax.vmap(gathered_kernels(fn)[name], in_axes=(0, None) + (0,) * n_args)
            label = _disk_label(fn)  # undulate's own energies: kept on disk, as single runs
            _RUN_KERNELS[key] = (CachedJit(k, f"batched.{label}.{name}.{n_args}") if label
                                 else jax.jit(k))
        return _RUN_KERNELS[key]

    def run(self, runs: Sequence[int], i: int, name: str, X: jnp.ndarray, *extra: jnp.ndarray,
            per_element: np.ndarray | None = None) -> list:
        """Kernel ``name`` of group ``i`` for ``runs`` at ``X`` (rows, n_nodes, 3): per chunk,
        the outputs with a leading row axis. ``extra`` (rows, ...) are global arguments of
        every call; ``per_element`` (rows, n_el, ...) is cut into chunks like the parameters."""
        g = self.ref.groups[i]
        rows = jnp.asarray(np.asarray(runs, dtype=np.int64))
        every = len(runs) == self.batch and list(runs) == list(range(self.batch))
        pe_chunks: list[tuple] = [()] * len(self._chunks[i])
        if per_element is not None:
            pe = np.asarray(per_element, dtype=np.float64)
            n_pad = sum(g._sizes)
            pe = np.concatenate([pe, np.zeros((pe.shape[0], n_pad - g.n_el) + pe.shape[2:])],
                                axis=1)
            pe_chunks = [(jnp.asarray(pe[:, s0 : s0 + m]),)
                         for s0, m in zip(g._starts, g._sizes, strict=True)]
        out = []
        for (nodes, params), pe_c in zip(self._chunks[i], pe_chunks, strict=True):
            args = (*(params if every else (p[rows] for p in params)), *pe_c, *extra)
            out.append(self._kernel(g.fn, name, len(args))(X, nodes, *args))
        return out

    def _joined(self, i: int, outs: Sequence, row: int) -> np.ndarray:
        """One row of group ``i``'s per-chunk outputs, over the group's elements."""
        return Assembly.joined(self.ref.groups[i], [np.asarray(o)[row] for o in outs])

    def energy(self, runs: Sequence[int], X: np.ndarray) -> list[float]:
        Xj = jnp.asarray(X)
        per_group = [self.run(runs, i, "per_element", Xj) for i in range(len(self.ref.groups))]
        return [float(sum(self._joined(i, o, r).sum() for i, o in enumerate(per_group)))
                for r in range(len(runs))]

    def gradient(self, runs: Sequence[int], X: np.ndarray) -> list[np.ndarray]:
        Xj = jnp.asarray(X)
        per_group = [self.run(runs, i, "grad", Xj) for i in range(len(self.ref.groups))]
        out = []
        for r, b in enumerate(runs):
            a = self.asms[b]
            g = a.gradient_from([self._joined(i, o, r) for i, o in enumerate(per_group)])
            out.append(g.ravel()[a.free_dofs])
        return out

    def stress_linearized(self, runs: Sequence[int], X: np.ndarray, dX: np.ndarray
                          ) -> list[dict[int, np.ndarray]]:
        Xj, dXj = jnp.asarray(X), jnp.asarray(dX)
        # the stress columns of the merit's kernel, as Assembly.stress_linearized
        outs = {i: self.run(runs, i, "merit_step", Xj, dXj) for i in self.ref.mixed_groups}
        return [{i: self._joined(i, o, r)[:, 2:] for i, o in outs.items()}
                for r in range(len(runs))]

    #: scatter element gradients and Hessians into the runs' arrays on the device (one
    #: indexed add per chunk for all rows) instead of on the host run by run: on an
    #: accelerator, where it saves copying every element Hessian back (not measured yet); not
    #: on a CPU, where it was slower (4 single rods: 108 s against 74 s; docs/benchmarks.md)
    DEVICE_SCATTER = jax.default_backend() != "cpu"

    def gradient_hessian(self, runs: Sequence[int], X: np.ndarray,
                         stress: Sequence[dict | None]
                         ) -> list[tuple[np.ndarray, sp.csc_matrix]]:
        """As :meth:`Assembly.gradient_hessian` per row (``stress[r]``: the row's carried
        stresses, or None for the consistent ones)."""
        Xj = jnp.asarray(X)
        mixed = self.ref.mixed_groups
        consistent = (self.stress_linearized(runs, X, np.zeros_like(X))
                      if any(s is None or set(mixed) - set(s) for s in stress) else None)
        per_group = []
        for i in range(len(self.ref.groups)):
            if i in mixed:
                s = np.stack([st[i] if st is not None and i in st else consistent[r][i]
                              for r, st in enumerate(stress)])
                per_group.append(self.run(runs, i, "grad_hess_mixed", Xj, per_element=s))
            else:
                per_group.append(self.run(runs, i, "grad_hess", Xj))
        if self.DEVICE_SCATTER:
            return self._scattered(runs, per_group)
        parts: list[list] = [[] for _ in runs]
        for i, outs in enumerate(per_group):
            for r, b in enumerate(runs):
                parts[r].append((self._joined(i, [o[0] for o in outs], r),
                                 self._joined(i, [o[1] for o in outs], r)
                                 .ravel()[self.asms[b]._keep[i]]))
        return [self.asms[b].grad_hess_from(p) for b, p in zip(runs, parts, strict=True)]

    @functools.cached_property
    def _scatter_maps(self) -> list[list[tuple[int, jnp.ndarray, jnp.ndarray, jnp.ndarray]]]:
        """Per group, per chunk: (real elements r, their dofs (r k 3,), the kept entries of
        the chunk's flattened element Hessians, where they go among the nnz values)."""
        ref = self.ref
        offs = np.concatenate([[0], np.cumsum([np.count_nonzero(k) for k in ref._keep])])
        maps = []
        for i, g in enumerate(ref.groups):
            d2 = (3 * g.k) ** 2
            keep = ref._keep[i].reshape(g.n_el, d2)
            before = np.concatenate([[0], np.cumsum(keep.sum(axis=1))])
            scatter = ref._scatter[offs[i] : offs[i + 1]]
            chunks = []
            for s0, m in zip(g._starts, g._sizes, strict=True):
                r = int(min(m, g.n_el - s0))
                dofs = (3 * g.nodes[s0 : s0 + r][:, :, None] + np.arange(3)).ravel()
                idx = np.nonzero(keep[s0 : s0 + r].ravel())[0]
                chunks.append((r, jnp.asarray(dofs), jnp.asarray(idx),
                               jnp.asarray(scatter[before[s0] : before[s0 + r]])))
            maps.append(chunks)
        return maps

    def _scattered(self, runs: Sequence[int], per_group: list[list]
                   ) -> list[tuple[np.ndarray, sp.csc_matrix]]:
        ref = self.ref
        rows = len(runs)
        gfull = jnp.zeros((rows, 3 * ref.n_nodes))
        hv = jnp.zeros((rows, ref.nnz))
        for outs, maps in zip(per_group, self._scatter_maps, strict=True):
            for (ge, he), (r, dofs, idx, dest) in zip(outs, maps, strict=True):
                gfull = gfull.at[:, dofs].add(ge[:, :r].reshape(rows, -1))
                hv = hv.at[:, dest].add(he.reshape(rows, -1)[:, idx])
        g = np.asarray(gfull)[:, ref.free_dofs]
        hv = np.asarray(hv)
        n = ref.n_free
        return [(g[r], sp.csc_matrix((hv[r], ref._indices, ref._indptr), shape=(n, n)))
                for r in range(rows)]

    def merit(self, runs: Sequence[int], X: np.ndarray, dX: np.ndarray
              ) -> list[tuple[float, float]]:
        Xj, dXj = jnp.asarray(X), jnp.asarray(dX)
        X1 = jnp.asarray(np.asarray(X) + np.asarray(dX))
        mixed = set(self.ref.mixed_groups)
        sums: list[list[tuple[float, float]]] = [[] for _ in runs]
        for i in range(len(self.ref.groups)):
            if i in mixed:
                outs = self.run(runs, i, "merit_step", Xj, dXj)
                for r in range(len(runs)):
                    me = self._joined(i, outs, r)[:, :2].sum(axis=0)
                    sums[r].append((float(me[0]), float(me[1])))
            else:
                outs = self.run(runs, i, "per_element", X1)
                for r in range(len(runs)):
                    e = float(self._joined(i, outs, r).sum())
                    sums[r].append((e, e))
        return [(sum(p[0] for p in ps), sum(p[1] for p in ps)) for ps in sums]
