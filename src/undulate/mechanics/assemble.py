"""Assembly of element energies into a global energy, gradient and sparse Hessian.

An :class:`ElementGroup` is one pure per-element energy function plus, for every element, the
node indices it reads and its parameters. The total energy is the sum over groups and elements.
Gradients and element Hessians come from JAX (``jax.grad``/``jax.hessian`` under ``jax.vmap``,
or closed forms and chain rules an energy function declares itself: the membrane, the hinges,
the rods' strain forms), jitted calls per group. Element Hessians are scattered into a sparse
pattern that is fixed for the mesh (computed once), so the sparse factorization's symbolic
analysis can be reused across Newton iterations and load steps.

Node slots may repeat inside an element (e.g. at rod ends): autodiff and the scatter-add both
sum such contributions, which is exactly the derivative of the composed function.
"""

from __future__ import annotations

import functools
import os
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .compiled import CachedJit

jax.config.update("jax_enable_x64", True)
# Compiled kernels are kept on disk (undulate.mechanics.compiled): the first run on a machine
# pays tracing and XLA's compilation (tens of seconds for the rod kernels), later runs and
# worker processes load the executables. JAX's own persistent compilation cache is not
# switched on: an executable it hands back cannot be written to undulate's cache again.

__all__ = ["ElementGroup", "Assembly", "StrainForm", "StrainTerm", "strain_form",
           "strain_form_kernels"]


#: element counts of kernel calls are padded to a multiple of this
PAD_TO = 16
#: most elements per kernel call
CALL_CAP = 4096
#: merit evaluations whose carried stresses an Assembly keeps for stress_linearized
MERIT_STRESSES_KEPT = 4


def _round_up(n: int, m: int) -> int:
    return -(-n // m) * m


@dataclass
class ElementGroup:
    """Elements sharing one energy function ``fn(x_local (k, 3), *params) -> scalar``."""

    name: str
    fn: Callable[..., jnp.ndarray]
    nodes: np.ndarray  # (n_el, k) int
    params: tuple[np.ndarray, ...]  # each (n_el, ...)
    chunk: int = 0  # elements per kernel call (0: all of them, at most CALL_CAP); fixed shapes
    #: where the elements sit among per-node frames shared with other groups (the rods:
    #: :class:`undulate.mechanics.frames.FrameSlots`); the Assembly then makes the Hessian of
    #: all groups on one layout through the frames, once per node (None: element by element)
    frames: object | None = None

    def __post_init__(self) -> None:
        self.nodes = np.asarray(self.nodes, dtype=np.int64)
        self.params = tuple(np.asarray(p, dtype=np.float64) for p in self.params)
        for p in self.params:
            if p.shape[0] != self.nodes.shape[0]:
                raise ValueError(f"group {self.name}: parameter rows != number of elements")

        if self.chunk <= 0:
            # one call over all the elements, padded to a multiple of PAD_TO, for groups up to
            # a cap: the kernels are compiled per mesh anyway (the node array's shape is part
            # of every kernel's signature), and each extra call shape costs a new process
            # about half a second to load for the rod kernels (measured on the demo). Calls
            # above the cap run slower per element (five rods at s = 50: 14,204 triangles
            # 14.7 ms in one call, 10.4 ms in calls of 4,096)
            self.chunk = min(CALL_CAP, _round_up(max(self.n_el, 1), PAD_TO))
        self._pad()

    def set_params(self, *params: np.ndarray) -> None:
        """Replace the element parameters (same shapes; the sparsity pattern is unchanged)."""
        new = tuple(np.asarray(p, dtype=np.float64) for p in params)
        if [p.shape for p in new] != [p.shape for p in self.params]:
            raise ValueError(f"group {self.name}: parameter shapes must not change")
        self.params = new
        self._pad()

    def _pieces(self) -> list[int]:
        """Sizes of the kernel calls over the elements: ``chunk`` as often as it fits, then the
        remainder padded to a multiple of :data:`PAD_TO` (two call shapes at most).

        The demo's 3,298 membrane triangles: one call of 3,312 (was 2,048 + 1,024 + 256, three
        programs to load in every new process).
        """
        n, c = self.n_el, self.chunk
        sizes = [c] * (n // c)
        r = n - c * (n // c)
        if r > 0:
            sizes.append(min(c, _round_up(r, PAD_TO)))
        return sizes

    def _pad(self) -> None:
        n = self.n_el
        self._sizes = self._pieces()
        n_pad = sum(self._sizes)
        idx = np.concatenate([np.arange(n), np.zeros(n_pad - n, dtype=np.int64)])
        # device arrays, chunked once (no host-to-device copies per evaluation); cut on the
        # host and put with jax.device_put: slicing a device array, and jnp.asarray, are JAX
        # programs compiled for each new shape (the demo's set-up: 41 of them, 0.24 s)
        nodes = np.asarray(self.nodes)[idx]
        params = [np.asarray(p)[idx] for p in self.params]
        starts = np.concatenate([[0], np.cumsum(self._sizes)])[:-1].astype(np.int64)
        self._chunks = [
            (jax.device_put(nodes[s0 : s0 + m]),
             tuple(jax.device_put(p[s0 : s0 + m]) for p in params))
            for s0, m in zip(starts, self._sizes, strict=True)
        ]
        self._starts = starts

    def run(self, kernel: str, x: jnp.ndarray, *extra, per_element: np.ndarray | None = None
            ) -> list:
        """Evaluate a kernel chunk by chunk over the padded elements (the padding is kept).

        ``extra`` are global arguments appended to every call; ``per_element`` (n_el, ...) is
        chunked like the parameters and appended after them.
        """
        kern = kernels_for(self.fn)[kernel]
        if per_element is None:
            return [kern(x, nodes, *params, *extra) for nodes, params in self._chunks]
        pe = np.asarray(per_element, dtype=np.float64)
        n_pad = sum(self._sizes)
        pe = np.concatenate([pe, np.zeros((n_pad - self.n_el,) + pe.shape[1:])])
        return [kern(x, nodes, *params, pe[s0 : s0 + m], *extra)
                for s0, m, (nodes, params) in zip(self._starts, self._sizes, self._chunks,
                                                   strict=True)]

    @property
    def n_el(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def k(self) -> int:
        return int(self.nodes.shape[1])


def _group_kernels(fn: Callable[..., jnp.ndarray]) -> dict[str, Callable]:
    def per_el(xl, *params):
        return jax.vmap(fn)(xl, *params)

    def grad_el(xl, *params):
        return jax.vmap(jax.grad(fn))(xl, *params)

    def hess_el(xl, *params):
        def flat(xf, *p):
            return fn(xf.reshape(-1, 3), *p)

        H = jax.vmap(jax.hessian(flat))(xl.reshape(xl.shape[0], -1), *params)
        return H

    def grad_hess_el(xl, *params):
        return grad_el(xl, *params), hess_el(xl, *params)

    return {"per_element": per_el, "grad": grad_el, "grad_hess": grad_hess_el}


def composite_kernels(
    block: Callable[[jnp.ndarray], jnp.ndarray], n_blocks: int, outer: Callable[..., jnp.ndarray]
) -> dict[str, Callable]:
    """Kernels of an energy ``outer(q, *params)`` of intermediates ``q = [block(x_b)]_b``.

    The element's nodes are ``n_blocks`` equal blocks; ``block`` maps one block (kb, 3) to m
    intermediate numbers. Chain rule: grad = J^T dq, Hessian = J^T Hq J + sum_i dq_i d2 q_i, with
    the block Hessians d2 q_i computed per block. Much cheaper to compile than differentiating
    the composed function twice (the rod's 15-node bending element: seconds instead of ~20 s).
    """

    def split(xl):
        kb = xl.shape[0] // n_blocks
        return xl.reshape(n_blocks, kb, 3)

    def energy(xl, *params):
        q = jax.vmap(block)(split(xl)).ravel()
        return outer(q, *params)

    def grad_one(xl, *params):
        xb = split(xl)
        q = jax.vmap(block)(xb)  # (nb, m)
        J = jax.vmap(jax.jacfwd(lambda y: block(y.reshape(-1, 3))))(xb.reshape(n_blocks, -1))
        dq = jax.grad(outer)(q.ravel(), *params).reshape(q.shape)
        return jnp.einsum("bm,bmi->bi", dq, J).reshape(xl.shape)

    def grad_hess_one(xl, *params):
        xb = split(xl)
        nb, kb, _ = xb.shape
        q = jax.vmap(block)(xb)
        m = q.shape[1]
        bflat = xb.reshape(nb, -1)

        def bf(y):
            return block(y.reshape(-1, 3))

        J = jax.vmap(jax.jacfwd(bf))(bflat)  # (nb, m, 3kb)
        dq = jax.grad(outer)(q.ravel(), *params).reshape(nb, m)
        Hq = jax.hessian(outer)(q.ravel(), *params).reshape(nb, m, nb, m)
        g = jnp.einsum("bm,bmi->bi", dq, J).reshape(xl.shape)
        H = jnp.einsum("bmi,bmcn,cnj->bicj", J, Hq, J)
        H = H + jnp.einsum("bij,bc->bicj", _weighted_block_hessians(bf, bflat, dq), jnp.eye(nb))
        n = nb * 3 * kb
        return g, H.reshape(n, n)

    return {
        "per_element": jax.vmap(energy),
        "grad": jax.vmap(grad_one),
        "grad_hess": jax.vmap(grad_hess_one),
    }


def _weighted_block_hessians(bf: Callable, yb: jnp.ndarray, c: jnp.ndarray) -> jnp.ndarray:
    """``sum_m c[b, m] d2 q_m(y_b)`` for every block b: the Hessian of one scalar, c_b . bf(y),
    per block, instead of the m Hessians of bf's outputs contracted afterwards (for the rod's
    frame, m = 9 outputs of 15 inputs: 9 times fewer second derivatives, the same sum)."""

    def one(y: jnp.ndarray, cb: jnp.ndarray) -> jnp.ndarray:
        return jax.hessian(lambda yy: jnp.dot(cb, bf(yy)))(y)

    return jax.vmap(one)(yb, c)


@dataclass(frozen=True)
class StrainTerm:
    """Some of an element's strains as a function of a *linear* projection of its intermediates:
    ``e_t = strains(P q, *params)`` with ``P = project(*params)`` (nz, n_q), constant in q.

    Splitting a strain vector into terms of few variables makes its second derivatives cheap:
    ``d2 (s . e) = sum_t P_t^T d2 (s_t . e_t) P_t`` needs the Hessians of small functions only
    (for the rod's bending and twist: 12 and 9 variables instead of all 27 intermediates;
    measured on the demo's 99 rod vertices: the mixed grad_hess kernel 7.5 -> 6.2 ms).
    """

    project: Callable[..., jnp.ndarray]
    strains: Callable[..., jnp.ndarray]


@dataclass(frozen=True)
class StrainForm:
    """An element energy written as ``0.5 * sum_i k_i e_i^2`` (a quadratic in strains).

    ``e = resid(q, *params)`` (m,) are the element's strains minus their rest values, of the
    intermediates ``q = [block(x_b)]_b`` of ``n_blocks`` equal node blocks (as in
    :func:`composite_kernels`); ``k = moduli(*params)`` (m,) their stiffnesses. Written this way,
    the Hessian splits into ``J^T k J`` and ``sum_i s_i d2 e_i`` with the stress ``s = k e``, and
    the Newton solver may evaluate the second term with a stress it carries itself (a mixed,
    stress-as-unknown Newton: see :mod:`undulate.solve.newton`).

    Instead of ``resid`` the strains may be given as ``terms`` (:class:`StrainTerm`), whose
    outputs, concatenated in order, are ``e``; the derivatives are then taken term by term.
    """

    block: Callable[[jnp.ndarray], jnp.ndarray]
    n_blocks: int
    resid: Callable[..., jnp.ndarray] | None
    moduli: Callable[..., jnp.ndarray]
    terms: tuple[StrainTerm, ...] = ()

    def __post_init__(self) -> None:
        if (self.resid is None) == (not self.terms):
            raise ValueError("StrainForm: give either resid or terms")

    def strains(self, q: jnp.ndarray, *params) -> jnp.ndarray:
        """``e`` (m,) of the intermediates ``q`` (flat)."""
        if self.resid is not None:
            return self.resid(q, *params)
        return jnp.concatenate([t.strains(t.project(*params) @ q, *params) for t in self.terms])

    def jacobian(self, q: jnp.ndarray, *params) -> jnp.ndarray:
        """``de/dq`` (m, n_q)."""
        if self.resid is not None:
            return jax.jacfwd(self.resid)(q, *params)
        parts = []
        for t in self.terms:
            P = t.project(*params)
            parts.append(jax.jacfwd(t.strains)(P @ q, *params) @ P)
        return jnp.concatenate(parts)

    def weighted_hessian(self, q: jnp.ndarray, s: jnp.ndarray, *params) -> jnp.ndarray:
        """``sum_i s_i d2 e_i / dq2`` (n_q, n_q)."""
        if self.resid is not None:
            return jax.hessian(lambda qq: jnp.dot(s, self.resid(qq, *params)))(q)
        out = jnp.zeros((q.size, q.size))
        i0 = 0
        for t in self.terms:
            P = t.project(*params)
            z = P @ q
            m = jax.eval_shape(t.strains, z, *params).shape[0]
            st = s[i0 : i0 + m]
            i0 += m
            Hz = jax.hessian(lambda zz, st=st, t=t: jnp.dot(st, t.strains(zz, *params)))(z)
            out = out + P.T @ Hz @ P
        return out


def strain_form_kernels(sf: StrainForm) -> dict[str, Callable]:
    """Batched kernels of a :class:`StrainForm` energy.

    ``grad_hess`` is the exact (consistent) pair; ``grad_hess_mixed(xl, *params, s)`` uses the
    given element stresses ``s`` (m,) in the geometric term; ``stress`` returns ``k e`` and
    ``stress_lin(xl, *params, dxl)`` the stress of the strains linearized at ``xl`` along
    ``dxl``, ``k (e + J dx)``; ``merit_step(xl, *params, dxl)`` the mixed merit and the energy
    at ``xl + dxl`` followed by that stress (2 + m,).
    """
    nb = sf.n_blocks

    def bf(y):
        return sf.block(y.reshape(-1, 3))

    def split(xl):
        return xl.reshape(nb, -1)

    def strains(xl, p):
        return sf.strains(jax.vmap(bf)(split(xl)).ravel(), *p)

    def energy(xl, *p):
        e = strains(xl, p)
        return 0.5 * jnp.sum(sf.moduli(*p) * e * e)

    def parts(xl, *p):
        xb = split(xl)
        q = jax.vmap(bf)(xb)  # (nb, mq)
        Jq = jax.vmap(jax.jacfwd(bf))(xb)  # (nb, mq, 3kb)
        e = sf.strains(q.ravel(), *p)
        Je = sf.jacobian(q.ravel(), *p)  # (m, nb*mq)
        return xb, q, Jq, e, Je

    def grad_one(xl, *p):
        _, q, Jq, e, Je = parts(xl, *p)
        dq = ((sf.moduli(*p) * e) @ Je).reshape(q.shape)
        return jnp.einsum("bm,bmi->bi", dq, Jq).reshape(xl.shape)

    def grad_hess_with(xl, p, s):
        xb, q, Jq, e, Je = parts(xl, *p)
        k = sf.moduli(*p)
        n_q = q.shape[1]
        g = jnp.einsum("bm,bmi->bi", ((k * e) @ Je).reshape(nb, n_q), Jq).reshape(xl.shape)
        s = k * e if s is None else s
        Hs = sf.weighted_hessian(q.ravel(), s, *p)
        Hq = (Je.T * k) @ Je + Hs
        Hq = Hq.reshape(nb, n_q, nb, n_q)
        dq = (s @ Je).reshape(nb, n_q)
        H = jnp.einsum("bmi,bmcn,cnj->bicj", Jq, Hq, Jq)
        H = H + jnp.einsum("bij,bc->bicj", _weighted_block_hessians(bf, xb, dq), jnp.eye(nb))
        n = xl.size
        return g, H.reshape(n, n)

    def grad_hess_one(xl, *p):
        return grad_hess_with(xl, p, None)

    def grad_hess_mixed_one(xl, *args):
        return grad_hess_with(xl, args[:-1], args[-1])

    def stress_one(xl, *p):
        return sf.moduli(*p) * strains(xl, p)

    def linearized_strains(xl, p, dxl):
        e, de = jax.jvp(lambda y: strains(y, p), (xl,), (dxl,))
        return e + de

    def stress_lin_one(xl, *args):
        p, dxl = args[:-1], args[-1]
        return sf.moduli(*p) * linearized_strains(xl, p, dxl)

    def merit_step_one(xl, *args):
        # at xl + dxl: the energy, and the mixed merit s e - s^2 / (2 k) with s = k e_lin the
        # stress of the strains linearized at xl (= the energy less k (e - e_lin)^2 / 2);
        # then s itself (what stress_lin returns for this step: the stress a Newton iteration
        # carries on when the line search takes the step)
        p, dxl = args[:-1], args[-1]
        e_lin = linearized_strains(xl, p, dxl)
        e1 = strains(xl + dxl, p)
        k = sf.moduli(*p)
        return jnp.concatenate([
            jnp.stack([jnp.sum(k * e_lin * (e1 - 0.5 * e_lin)), 0.5 * jnp.sum(k * e1 * e1)]),
            k * e_lin])

    return {
        "per_element": jax.vmap(energy),
        "grad": jax.vmap(grad_one),
        "grad_hess": jax.vmap(grad_hess_one),
        "grad_hess_mixed": jax.vmap(grad_hess_mixed_one),
        "stress": jax.vmap(stress_one),
        "stress_lin": jax.vmap(stress_lin_one),
        "merit_step": jax.vmap(merit_step_one),
    }


def strain_form(fn: Callable) -> StrainForm | None:
    """The :class:`StrainForm` an energy function declares (attribute ``strain_form``), or None."""
    sf = getattr(fn, "strain_form", None)
    return sf if isinstance(sf, StrainForm) else None


_KERNEL_CACHE: dict[Callable, dict[str, Callable]] = {}
_RAW_CACHE: dict[Callable, dict[str, Callable]] = {}
#: kernels whose last argument is a global (n_nodes, 3) array gathered like the positions
GATHER_LAST = ("stress_lin", "merit_step")


def gathered_kernels(fn: Callable[..., jnp.ndarray]) -> dict[str, Callable]:
    """The kernels of one element energy as plain (not jitted) functions
    ``kernel(x (n_nodes, 3), nodes (chunk, k), *params)``: what :func:`kernels_for` jits, and
    what a batched evaluation maps over runs (:mod:`undulate.mechanics.batched`).

    An energy function may carry its own batched kernels (attribute ``kernels``, e.g. made by
    :func:`composite_kernels`); otherwise they are made by plain autodiff.
    """
    if fn not in _RAW_CACHE:
        sf = strain_form(fn)
        custom = getattr(fn, "kernels", None)
        if sf is not None:
            batched = strain_form_kernels(sf)
        else:
            batched = custom() if callable(custom) else _group_kernels(fn)
        _RAW_CACHE[fn] = {name: _gathered(k, name in GATHER_LAST)
                          for name, k in batched.items()}
    return _RAW_CACHE[fn]


def kernels_for(fn: Callable[..., jnp.ndarray]) -> dict[str, Callable]:
    """Jitted kernels of one element energy (cached per function, shared by all assemblies),
    called as ``kernel(x (n_nodes, 3), nodes (chunk, k), *params)`` (:func:`gathered_kernels`).

    Gathering the element's nodes inside the compiled function avoids one eager JAX gather
    per chunk (about 1 ms each on CPU, measured), which dominated cheap kernels. Module-level
    energies of undulate itself are also kept on disk as traced programs (:class:`CachedJit`).
    """
    if fn not in _KERNEL_CACHE:
        label = _disk_label(fn)
        _KERNEL_CACHE[fn] = {
            name: CachedJit(k, f"{label}.{name}") if label else jax.jit(k)
            for name, k in gathered_kernels(fn).items()
        }
    return _KERNEL_CACHE[fn]


def _disk_label(fn: Callable) -> str | None:
    """A name that identifies an energy function across processes, or None.

    Only module-level functions of undulate itself qualify (their code is part of the disk
    cache's key, :mod:`undulate.mechanics.compiled`); a function defined elsewhere (a test, a
    user's own energy) or a closure is jitted afresh in every process.
    """
    mod, qual = getattr(fn, "__module__", ""), getattr(fn, "__qualname__", "")
    if not mod.startswith("undulate.") or "<" in qual:
        return None
    return f"{mod.removeprefix('undulate.')}.{qual}"


def _gathered(kernel: Callable, gather_last: bool = False) -> Callable:
    """``kernel(x[nodes], *params)`` as one function ``(x, nodes, *params)``; with
    ``gather_last`` the last argument is a global (n_nodes, 3) array gathered the same way."""

    def gathered(x, nodes, *params):
        if gather_last:
            return kernel(x[nodes], *params[:-1], params[-1][nodes])
        return kernel(x[nodes], *params)

    return gathered


@functools.cache
def _pool() -> ThreadPoolExecutor:
    """Threads that evaluate element groups concurrently (2 at most: the kernels themselves
    use XLA's threads too; on the 2-core machine the demo's assembly went 33 -> 27 ms)."""
    return ThreadPoolExecutor(max_workers=max(1, min(2, os.cpu_count() or 1)),
                              thread_name_prefix="undulate-assembly")


class Assembly:
    """Global energy of ``n_nodes`` 3D nodes; the unknowns are the components not in ``fixed``.

    ``fixed`` is a boolean (n_nodes, 3) mask of prescribed coordinates. The sparse Hessian over
    the free unknowns is returned as the upper triangle in CSC format (the form LDL^T solvers
    take) with a pattern computed once here.
    """

    def __init__(self, n_nodes: int, groups: Sequence[ElementGroup], fixed: np.ndarray) -> None:
        self.n_nodes = int(n_nodes)
        self.groups = [g for g in groups if g.n_el > 0]
        self.fixed = np.asarray(fixed, dtype=bool).reshape(n_nodes, 3)
        free = ~self.fixed.ravel()
        self.free_dofs = np.nonzero(free)[0]
        self.n_free = int(self.free_dofs.size)
        dof_map = -np.ones(3 * n_nodes, dtype=np.int64)
        dof_map[self.free_dofs] = np.arange(self.n_free)
        self._dof_map = dof_map
        self._build_pattern()
        #: (x, dx, parameters, stresses) of the last merit evaluations (stress_linearized)
        self._merit_stresses: deque = deque(maxlen=MERIT_STRESSES_KEPT)
        from .frames import fused_frame_sets

        #: strain-form groups on shared frames, whose Hessian is made through the frames
        #: (:mod:`undulate.mechanics.frames`); empty: every group element by element
        self.fused = fused_frame_sets(self)
        self._fused_groups = {i for f in self.fused for i in f.indices}
        if self.fused:
            offs = np.concatenate([[0], np.cumsum([np.count_nonzero(k) for k in self._keep])])
            #: per task of gradient_hessian (own groups in order, then the fused sets): the
            #: places in the Hessian's values of the entries it returns
            self._task_scatter = [self._scatter[offs[i] : offs[i + 1]]
                                  for i in range(len(self.groups))
                                  if i not in self._fused_groups] + \
                [np.asarray(f.positions) for f in self.fused]

    # ------------------------------------------------------------------ pattern
    def _build_pattern(self) -> None:
        rows_all, cols_all, keep_all = [], [], []
        for g in self.groups:
            dofs = (3 * g.nodes[:, :, None] + np.arange(3)).reshape(g.n_el, -1)  # (n_el, 3k)
            fd = self._dof_map[dofs]
            r = np.repeat(fd[:, :, None], fd.shape[1], axis=2).ravel()
            c = np.repeat(fd[:, None, :], fd.shape[1], axis=1).ravel()
            keep = (r >= 0) & (c >= 0) & (r <= c)
            rows_all.append(r[keep])
            cols_all.append(c[keep])
            keep_all.append(keep)
        rows = np.concatenate(rows_all) if rows_all else np.zeros(0, np.int64)
        cols = np.concatenate(cols_all) if cols_all else np.zeros(0, np.int64)
        n = self.n_free
        # diagonal always present (so a shift can be added in place)
        rows = np.concatenate([rows, np.arange(n)])
        cols = np.concatenate([cols, np.arange(n)])
        lin = cols * n + rows  # CSC order: by column, then row
        uniq, inv = np.unique(lin, return_inverse=True)
        self._scatter = inv[: rows.size - n]
        self._keep = keep_all
        self._kept_index: dict[int, list[np.ndarray]] = {}
        self.nnz = int(uniq.size)
        ucol = uniq // n
        urow = uniq % n
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.add.at(indptr, ucol + 1, 1)
        indptr = np.cumsum(indptr)
        self._indices = urow.astype(np.int32)
        self._indptr = indptr.astype(np.int32)
        self.diag_pos = inv[rows.size - n :]
        # the full symmetric matrix's CSR pattern and, per entry, the upper entry it copies
        # (forming it with sparse additions took 2.2 ms per Newton iteration on the demo)
        pos = sp.csc_matrix((np.arange(1, self.nnz + 1, dtype=np.float64), self._indices,
                             self._indptr), shape=(n, n))
        full = (pos + sp.triu(pos, k=1, format="csc").T).tocsr()
        full.sort_indices()
        self._full_from_upper = full.data.astype(np.int64) - 1
        self._full_indices = full.indices
        self._full_indptr = full.indptr

    # ------------------------------------------------------------------ helpers
    def full(self, u: np.ndarray, x_fixed: np.ndarray) -> np.ndarray:
        """Node positions (n_nodes, 3) from free unknowns ``u`` and prescribed positions."""
        x = np.array(x_fixed, dtype=np.float64).ravel()
        x[self.free_dofs] = u
        return x.reshape(self.n_nodes, 3)

    def free(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x, dtype=np.float64).ravel()[self.free_dofs]

    # ------------------------------------------------------------------ evaluation
    @staticmethod
    def joined(g: ElementGroup, outs: Sequence) -> np.ndarray:
        """One group's per-chunk kernel outputs as one array over its elements (padding off)."""
        return np.concatenate([np.asarray(o) for o in outs])[: g.n_el]

    def _per_element(self, g: ElementGroup, xj: jnp.ndarray) -> np.ndarray:
        return self.joined(g, g.run("per_element", xj))

    def energy(self, x: np.ndarray) -> float:
        xj = jnp.asarray(x)
        return float(sum(self._per_element(g, xj).sum() for g in self.groups))

    def energy_by_group(self, x: np.ndarray) -> dict[str, float]:
        xj = jnp.asarray(x)
        out: dict[str, float] = {}
        for g in self.groups:
            out[g.name] = out.get(g.name, 0.0) + float(self._per_element(g, xj).sum())
        return out

    def element_energies(self, x: np.ndarray, name: str) -> np.ndarray:
        """Energy of every element of the groups called ``name`` (concatenated)."""
        xj = jnp.asarray(x)
        parts = [self._per_element(g, xj) for g in self.groups if g.name == name]
        return np.concatenate(parts) if parts else np.zeros(0)

    def _scatter_nodes(self, g: ElementGroup, ge: np.ndarray, out: np.ndarray) -> None:
        flat_nodes = g.nodes.ravel()
        ge = ge.reshape(-1, 3)
        for c in range(3):
            out[:, c] += np.bincount(flat_nodes, weights=ge[:, c], minlength=self.n_nodes)

    def gradient_full(self, x: np.ndarray) -> np.ndarray:
        """Gradient with respect to all node coordinates, (n_nodes, 3)."""
        xj = jnp.asarray(x)
        return self.gradient_from([self.joined(g, g.run("grad", xj)) for g in self.groups])

    def gradient_from(self, ges: Sequence[np.ndarray], which: Sequence[int] | None = None
                      ) -> np.ndarray:
        """Gradient (n_nodes, 3) from the groups' element gradients (of all groups, or of the
        groups ``which``), summed in group order."""
        gfull = np.zeros((self.n_nodes, 3))
        groups = self.groups if which is None else [self.groups[i] for i in which]
        for g, ge in zip(groups, ges, strict=True):
            self._scatter_nodes(g, ge, gfull)
        return gfull

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return self.gradient_full(x).ravel()[self.free_dofs]

    def gradient_hessian(self, x: np.ndarray, stress: dict[int, np.ndarray] | None = None
                         ) -> tuple[np.ndarray, sp.csc_matrix]:
        """Free gradient and the upper triangle (CSC) of the free Hessian.

        ``stress`` maps the index of a strain-form group (:attr:`mixed_groups`) to element
        stresses (n_el, m) to use in that group's geometric Hessian term instead of the
        consistent ``k e(x)`` (mixed Newton). The gradient is always the exact one.
        """
        xj = jnp.asarray(x)
        mixed = set(self.mixed_groups)

        def stress_of(i: int) -> np.ndarray:
            return stress[i] if stress is not None and i in stress else self._stress(i, xj)

        def one(i: int) -> tuple[np.ndarray, np.ndarray]:
            g = self.groups[i]
            if i in mixed:
                # the consistent pair is the mixed one at the stresses k e(x): one compiled
                # program serves both (each costs a new process ~0.4 s to load for the rods)
                outs = g.run("grad_hess_mixed", xj, per_element=stress_of(i))
            else:
                outs = g.run("grad_hess", xj)
            return self.joined(g, [o[0] for o in outs]), self._kept(i, [o[1] for o in outs])

        if not self.fused:
            # the groups' kernels run side by side on the machine's cores (JAX releases the
            # GIL); results are summed in group order afterwards, so the sum does not depend
            # on timing
            return self.grad_hess_from(list(_pool().map(one, range(len(self.groups)))))
        own = [i for i in range(len(self.groups)) if i not in self._fused_groups]

        def task(k: int):
            if k < len(own):
                ge, v = one(own[k])
            else:
                f = self.fused[k - len(own)]
                ge, v = f.run(xj, [stress_of(i) for i in f.indices])
            # each task sums its own entries into the Hessian's values, beside the other
            # tasks' kernels (NumPy lets go of the GIL for part of it; five rods at s = 50:
            # one bincount of all 2.6 M entries after the kernels took 8.9 ms, their
            # concatenation 3.1 ms)
            return ge, np.bincount(self._task_scatter[k], weights=v, minlength=self.nnz)

        parts = list(_pool().map(task, range(len(own) + len(self.fused))))
        gfull = self.gradient_from([p[0] for p in parts[: len(own)]], own)
        for gr, _ in parts[len(own):]:
            gfull += gr
        data = parts[0][1]
        for _, d in parts[1:]:  # in task order: the sum does not depend on timing
            data += d
        H = sp.csc_matrix((data, self._indices, self._indptr), shape=(self.n_free, self.n_free))
        return gfull.ravel()[self.free_dofs], H

    def grad_hess_from(self, parts: Sequence[tuple[np.ndarray, np.ndarray]]
                       ) -> tuple[np.ndarray, sp.csc_matrix]:
        """(free gradient, upper Hessian) from each group's element gradients and its kept
        element Hessian entries (``He.ravel()[keep]``), summed in group order."""
        gfull = self.gradient_from([p[0] for p in parts])
        v = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0)
        data = np.bincount(self._scatter, weights=v, minlength=self.nnz)
        H = sp.csc_matrix((data, self._indices, self._indptr), shape=(self.n_free, self.n_free))
        return gfull.ravel()[self.free_dofs], H

    def _kept(self, i: int, chunks: Sequence) -> np.ndarray:
        """Group ``i``'s kept Hessian entries (those ``_keep`` selects, in its order) from the
        kernel's per-chunk element Hessians, taken chunk by chunk with integer indices: no
        joined copy of the whole padded array and no boolean mask (five rods at s = 50, the
        hinges' 3.05 M entries: 5.7 ms joined and masked, about 2 ms this way)."""
        idx = self._kept_index.get(i)
        if idx is None:
            g, keep = self.groups[i], self._keep[i]
            d2 = keep.size // max(g.n_el, 1)
            idx = []
            for s0, m in zip(g._starts, g._sizes, strict=True):
                real = max(0, min(m, g.n_el - int(s0)))
                idx.append(np.flatnonzero(keep[int(s0) * d2 : (int(s0) + real) * d2]))
            self._kept_index[i] = idx
        parts = [np.asarray(c).reshape(-1).take(ix) for c, ix in zip(chunks, idx, strict=True)]
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    @functools.cached_property
    def mixed_groups(self) -> list[int]:
        """Indices of the groups written in strain form (their stresses can be carried)."""
        return [i for i, g in enumerate(self.groups) if strain_form(g.fn) is not None]

    def stress(self, x: np.ndarray) -> dict[int, np.ndarray]:
        """Consistent element stresses ``k e(x)`` of the strain-form groups."""
        xj = jnp.asarray(x)
        return {i: self._stress(i, xj) for i in self.mixed_groups}

    def _stress(self, i: int, xj: jnp.ndarray) -> np.ndarray:
        # k (e + J 0) = k e through the merit's kernel, which every mixed Newton iteration
        # loads anyway (the same numbers as the "stress" kernel)
        return self._stress_lin(i, xj, jnp.zeros_like(xj))

    def _stress_lin(self, i: int, xj: jnp.ndarray, dj: jnp.ndarray) -> np.ndarray:
        # k (e + J dx): the stress columns of the merit's kernel, so that a step's carried
        # stresses are the same numbers whether its merit was evaluated or not (a kernel of
        # their own gave other roundoff; and it is one program less to load)
        g = self.groups[i]
        return self.joined(g, g.run("merit_step", xj, dj))[:, 2:]

    def stress_linearized(self, x: np.ndarray, dx: np.ndarray) -> dict[int, np.ndarray]:
        """Stresses of the strains linearized at ``x`` and moved by ``dx``: ``k (e + J dx)``.

        A step whose merit :meth:`merit` evaluated lately (the one a line search took) has
        them already: the same numbers, from the merit's kernel.
        """
        params = self._mixed_params()
        for xm, dxm, pm, st in self._merit_stresses:
            if pm == params and np.array_equal(xm, x) and np.array_equal(dxm, dx):
                return dict(st)
        xj, dj = jnp.asarray(x), jnp.asarray(np.asarray(dx, dtype=np.float64))
        return {i: self._stress_lin(i, xj, dj) for i in self.mixed_groups}

    def _mixed_params(self) -> tuple[int, ...]:
        # which parameters the strain-form groups had (ElementGroup.set_params replaces the
        # tuple): kept stresses of other parameters are not reused
        return tuple(id(self.groups[i].params) for i in self.mixed_groups)

    def merit(self, x: np.ndarray, dx: np.ndarray) -> tuple[float, float]:
        """(merit, energy) at ``x + dx``: the merit of a mixed Newton step from ``x``.

        The merit is the energy with each strain-form group's quadratic term evaluated as the
        Hellinger-Reissner functional ``s e - s^2 / (2 k)`` at the stress ``s = k e_lin`` of
        the strains linearized at ``x`` (the stress a mixed Newton step carries), i.e. the
        energy less ``k (e - e_lin)^2 / 2``: the second-order stretch that a straight step
        gives a rotating stiff rod is not charged to the step (the next iteration removes it).
        """
        xj, dj = jnp.asarray(x), jnp.asarray(np.asarray(dx, dtype=np.float64))
        x1 = jnp.asarray(np.asarray(x) + np.asarray(dx))
        mixed = set(self.mixed_groups)

        stresses: dict[int, np.ndarray] = {}

        def one(i: int) -> tuple[float, float]:
            g = self.groups[i]
            if i in mixed:
                out = self.joined(g, g.run("merit_step", xj, dj))
                stresses[i] = out[:, 2:]
                me = out[:, :2].sum(axis=0)
                return float(me[0]), float(me[1])
            e = float(self._per_element(g, x1).sum())
            return e, e

        # groups side by side as in gradient_hessian, summed in group order
        parts = list(_pool().map(one, range(len(self.groups))))
        # the last few steps' stresses, for stress_linearized of the step a line search takes
        # (a curved search's expansion evaluates one step past the one it keeps)
        self._merit_stresses.appendleft((np.array(x, dtype=np.float64),
                                         np.array(dx, dtype=np.float64), self._mixed_params(),
                                         stresses))
        return sum(p[0] for p in parts), sum(p[1] for p in parts)

    def symmetric(self, H_upper: sp.csc_matrix) -> sp.csr_matrix:
        """Full symmetric matrix from its upper triangle (a Hessian of this assembly's
        pattern: its entries are copied through a map made once)."""
        same = (H_upper.nnz == self.nnz and H_upper.shape == (self.n_free, self.n_free)
                and (np.shares_memory(H_upper.indptr, self._indptr)
                     or (np.array_equal(H_upper.indptr, self._indptr)
                         and np.array_equal(H_upper.indices, self._indices))))
        if not same:
            d = H_upper.diagonal()
            return (H_upper + H_upper.T - sp.diags(d)).tocsr()
        # the index arrays are copied: a caller's in-place change of the result's structure
        # (eliminate_zeros, prune) must not reach the map
        return sp.csr_matrix((H_upper.data[self._full_from_upper], self._full_indices.copy(),
                              self._full_indptr.copy()), shape=H_upper.shape)
