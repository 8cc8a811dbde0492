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

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .assemble import Assembly

__all__ = ["BatchedAssembly"]


class BatchedAssembly:
    """Energy, free gradient and upper Hessian values of ``B`` runs with one topology.

    ``assemblies``: one :class:`Assembly` per run, with the same nodes, fixed mask and
    element groups (same names, energy functions and node lists); only the groups'
    parameters may differ. Evaluate at ``X`` of shape (B, n_nodes, 3).
    """

    def __init__(self, assemblies: Sequence[Assembly]) -> None:
        if not assemblies:
            raise ValueError("BatchedAssembly: no runs given")
        ref = assemblies[0]
        for k, a in enumerate(assemblies[1:], start=1):
            if a.n_nodes != ref.n_nodes or not np.array_equal(a.fixed, ref.fixed):
                raise ValueError(f"BatchedAssembly: run {k} has other nodes or clamps")
            if [(g.name, g.fn) for g in a.groups] != [(g.name, g.fn) for g in ref.groups]:
                raise ValueError(f"BatchedAssembly: run {k} has other element groups")
            for g, h in zip(a.groups, ref.groups, strict=True):
                if not np.array_equal(g.nodes, h.nodes):
                    raise ValueError(f"BatchedAssembly: run {k}, group {g.name}: other nodes")
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
