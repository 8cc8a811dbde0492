"""Strain-form groups whose elements share per-node frames, assembled through the frames.

The rods' stretch and bend/twist energies (:mod:`undulate.mechanics.rod`) are strain forms
(:class:`~undulate.mechanics.forms.StrainForm`) of per-node intermediates: each rod node k
has a *frame* ``q_k = block(x_k)`` (for the rods ``frame_point``: the fabric point p under the
centre line, the fabric normal n and the footprint's width vector w, from the node's stencil of
five fabric points), and an element reads the frames of consecutive nodes (an edge two, a
bending vertex three). Element by element, every element pays the chain rule through each of
its frames: the Hessian of a bending element is 45 x 45, ``J^T Hq J`` with 27 frame numbers,
plus the second derivatives of its three frames, so each node's frame is differentiated twice
over five times (two edges, three vertices), and 2,025 entries per vertex are scattered.

Here the elements' gradients and Hessians are taken with respect to the frames only and summed
per node and per pair of nodes ``(k, k + delta)`` first; each node's frame is then
differentiated once, and the Hessian comes out as one 15 x 15 block per node and per coupled
pair:

    g = sum_k J_k^T gq_k,
    H = sum_k (J_k^T B_k0 J_k + sum_m c_km d2 q_km) + sum_{k, delta > 0} (J_k^T B_k,delta
        J_k+delta + transpose),

with ``J_k = dq_k / dx``, ``gq_k`` and ``B`` the summed frame-space gradients and Hessian
blocks of the elements, and ``c_k`` the frame-space forces of the geometric term (the carried
stresses of the mixed Newton where it carries them, as element by element). The numbers are
those of the element-by-element assembly to roundoff (``tests/test_frames.py``); the rod part
of one Hessian costs a quarter to a third of the time (docs/benchmarks.md, thirteenth pass).

The per-element and per-node derivatives run in chunks of :data:`CHUNK` rows (``lax.map`` over
``vmap``-ed chunks) once there are more than two chunks' worth: XLA on the CPU runs a small
batch of these small Hessians several times faster per element than one large batch
(measured: the twist term's Hessians of 505 vertices 5.3 ms in one batch, 1.2 ms in chunks of
32 to 101), but a loop of two chunks costs more than one batch of up to 128.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["FrameLayout", "FrameSlots", "FusedFrames", "chunked_vmap", "fused_frame_sets"]

#: rows per chunk of the per-element and per-node derivatives (32, 64, 128 measured on five
#: rods at s = 50: 12.0, 8.5, 12.6 ms for the fused rod kernel)
CHUNK = 64


@dataclass(eq=False)
class FrameLayout:
    """The blocks that frames are made of: ``nodes[k]`` (kb node indices) is block k, and
    ``block(x_k (kb, 3))`` its frame. One layout is shared (by identity) by the groups whose
    elements read its frames."""

    nodes: np.ndarray
    block: Callable[[jnp.ndarray], jnp.ndarray]

    def __post_init__(self) -> None:
        self.nodes = np.asarray(self.nodes, dtype=np.int64)


@dataclass(eq=False)
class FrameSlots:
    """Where a strain-form group's elements sit in a :class:`FrameLayout`: element i reads the
    blocks ``first[i], first[i] + 1, ..., first[i] + n_blocks - 1``."""

    layout: FrameLayout
    first: np.ndarray

    def __post_init__(self) -> None:
        self.first = np.asarray(self.first, dtype=np.int64)


def chunked_vmap(f: Callable, chunk: int | None = None) -> Callable:
    """``jax.vmap(f)`` over the leading axis of every argument, evaluated in chunks of
    ``chunk`` rows (default :data:`CHUNK`) by ``lax.map``; the last chunk is filled up with
    copies of the last row, whose results are dropped."""

    def g(*args):
        c = chunk or CHUNK
        n = args[0].shape[0]
        if n <= 2 * c:
            # one batch up to two chunks: a loop of two costs more than the larger batch
            # (the demo's 101 rod nodes: the fused rod kernel 2.5 -> 1.8 ms)
            return jax.vmap(f)(*args)
        m = -(-n // c)
        pad = m * c - n

        def prep(a):
            if pad:
                a = jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)])
            return a.reshape((m, c) + a.shape[1:])

        out = jax.lax.map(lambda xs: jax.vmap(f)(*xs), tuple(prep(a) for a in args))
        return jax.tree_util.tree_map(lambda o: o.reshape((m * c,) + o.shape[2:])[:n], out)

    return g


def _ahead(a: jnp.ndarray, k: int) -> jnp.ndarray:
    """Row i + k of ``a`` at row i (zeros past the end)."""
    if k == 0:
        return a
    return jnp.concatenate([a[k:], jnp.zeros((k,) + a.shape[1:], a.dtype)])


def _behind(a: jnp.ndarray, k: int) -> jnp.ndarray:
    """Row i - k of ``a`` at row i (zeros before the start)."""
    if k == 0:
        return a
    return jnp.concatenate([jnp.zeros((k,) + a.shape[1:], a.dtype), a[:-k]])


def _add_form(sf, nb: int, mq: int, qe, valid, stress, params, gq, cq, B: list):
    """Add one strain form's gradient, stress and Hessian blocks (per frame, ``nb`` frames an
    element) onto the layout's ``gq``, ``cq`` and ``B`` (B in place); return (gq, cq)."""

    def one(qv, s, *p):
        e = sf.strains(qv, *p)
        Je = sf.jacobian(qv, *p)
        k = sf.moduli(*p)
        Hq = (Je.T * k) @ Je + sf.weighted_hessian(qv, s, *p)
        return (k * e) @ Je, Hq, s @ Je

    ge, He, ce = chunked_vmap(one)(qe, stress, *params)
    v = valid > 0
    ge = jnp.where(v[:, None], ge, 0.0)
    ce = jnp.where(v[:, None], ce, 0.0)
    He = jnp.where(v[:, None, None], He, 0.0)
    for i in range(nb):
        gq = gq + _behind(ge[:, i * mq : (i + 1) * mq], i)
        cq = cq + _behind(ce[:, i * mq : (i + 1) * mq], i)
        for j in range(i, nb):
            B[j - i] = B[j - i] + _behind(
                He[:, i * mq : (i + 1) * mq, j * mq : (j + 1) * mq], i)
    return gq, cq


def _fused_kernel(block: Callable, forms: tuple, n_blocks: tuple[int, ...],
                  n_params: tuple[int, ...]) -> Callable:
    """The jittable kernel of the groups with strain forms ``forms`` (``n_blocks`` blocks and
    ``n_params`` parameter arrays each) on one layout:
    ``kernel(x, nodes, fill, *[valid, params..., stress] per group)`` ->
    ``(g_nodes (M, 3 kb), H_0 (M, 3kb, 3kb), H_1, ..., H_D)``, D = max n_blocks - 1.

    ``valid`` (M,) marks the slots where an element of the group starts, ``params`` and
    ``stress`` are laid out by start slot; ``fill`` (n_groups,) is a valid slot of each group
    whose frames stand in for the missing ones (past a rod's end), so every derivative is
    finite before it is masked.
    """
    D = max(n_blocks) - 1

    def bf(y):
        return block(y.reshape(-1, 3))

    def kernel(x, nodes, fill, *gargs):
        M, kb = nodes.shape
        y = x[nodes].reshape(M, 3 * kb)
        q = jax.vmap(bf)(y)  # (M, m)
        J = jax.vmap(jax.jacfwd(bf))(y)  # (M, m, 3 kb)
        mq = q.shape[1]
        gq = jnp.zeros((M, mq))
        cq = jnp.zeros((M, mq))
        B = [jnp.zeros((M, mq, mq)) for _ in range(D + 1)]
        pos = 0
        for t, (sf, nb) in enumerate(zip(forms, n_blocks, strict=True)):
            n_par = n_params[t]
            valid, params = gargs[pos], gargs[pos + 1 : pos + 1 + n_par]
            stress = gargs[pos + 1 + n_par]
            pos += n_par + 2
            qe = jnp.concatenate([_ahead(q, j) for j in range(nb)], axis=1)  # (M, nb m)
            qe = jnp.where(valid[:, None] > 0, qe, qe[fill[t]])
            gq, cq = _add_form(sf, nb, mq, qe, valid, stress, params, gq, cq, B)

        def weighted(yk, ck):
            return jax.hessian(lambda z: jnp.dot(ck, bf(z)))(yk)

        W = chunked_vmap(weighted)(y, cq)
        g_nodes = jnp.einsum("ma,mai->mi", gq, J)
        H = [jnp.einsum("mai,mab,mbj->mij", J, B[0], J) + W]
        for dlt in range(1, D + 1):
            H.append(jnp.einsum("mai,mab,mbj->mij", J, B[dlt], _ahead(J, dlt)))
        return (g_nodes, *H)

    return kernel


_KERNELS: dict[tuple, Callable] = {}


def _kernel_for(block: Callable, forms: tuple, n_blocks: tuple, n_params: tuple,
                label: str | None) -> Callable:
    key = (block, forms, n_blocks, n_params)
    if key not in _KERNELS:
        from .compiled import CachedJit

        k = _fused_kernel(block, forms, n_blocks, n_params)
        _KERNELS[key] = CachedJit(k, label) if label else jax.jit(k)
    return _KERNELS[key]


class FusedFrames:
    """The gradient and Hessian of the strain-form groups ``indices`` of ``asm`` that share one
    :class:`FrameLayout`, assembled through the frames (module docstring).

    :meth:`run` returns the gradient over all nodes (n_nodes, 3) and the Hessian values with
    their positions in ``asm``'s upper CSC pattern (the groups' own pattern, so nothing
    changes in it).
    """

    def __init__(self, asm, indices: Sequence[int]) -> None:
        from .forms import strain_form

        self.indices = list(indices)
        groups = [asm.groups[i] for i in self.indices]
        layout = groups[0].frames.layout
        self.layout = layout
        forms = tuple(strain_form(g.fn) for g in groups)
        nbs = tuple(sf.n_blocks for sf in forms)
        M, kb = layout.nodes.shape
        self.M = M
        for g, sf in zip(groups, forms, strict=True):
            if sf.block is not layout.block:
                raise ValueError(f"group {g.name}: its strain form's block is not the layout's")
            first = g.frames.first
            fits = first.size == g.n_el and first.min(initial=0) >= 0 \
                and first.max(initial=0) + sf.n_blocks <= M
            if not fits or not np.array_equal(g.nodes, np.concatenate(
                    [layout.nodes[first + j] for j in range(sf.n_blocks)], axis=1)):
                raise ValueError(f"group {g.name}: its elements are not the layout's blocks")
            if np.unique(first).size != first.size:
                raise ValueError(f"group {g.name}: two elements start at one block")
        self.groups = groups
        self.n_blocks = nbs
        self.D = max(nbs) - 1
        # jax.device_put, not jnp.asarray (a program compiled per new shape)
        self._nodes = jax.device_put(layout.nodes)
        self._fill = jax.device_put(np.array([int(g.frames.first[0]) for g in groups]))
        self._valid = [jax.device_put(np.isin(np.arange(M), g.frames.first).astype(float))
                       for g in groups]
        self._params_key: tuple | None = None
        self._params: list = []
        mod = [getattr(g.fn, "__module__", "") for g in groups]
        label = None
        if all(m.startswith("undulate.") for m in mod):
            label = "frames." + "+".join(g.fn.__qualname__ for g in groups)
        self._kernel = _kernel_for(layout.block, forms, nbs,
                                   tuple(len(g.params) for g in groups), label)
        self._build_scatter(asm, kb)

    # -------------------------------------------------------------- scatter map
    def _build_scatter(self, asm, kb: int) -> None:
        n = asm.n_free
        # the upper CSC pattern as sorted codes col * n + row
        cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(asm._indptr))
        codes = cols * n + asm._indices.astype(np.int64)
        dm = asm._dof_map
        nodes = self.layout.nodes
        M = self.M
        dofs = dm[(3 * nodes[:, :, None] + np.arange(3)).reshape(M, 3 * kb)]  # (M, 3 kb)
        # pairs of blocks (k, k + delta) that some element couples
        coupled = np.zeros((self.D + 1, M), dtype=bool)
        coupled[0, :] = True
        for g, nb in zip(self.groups, self.n_blocks, strict=True):
            for dlt in range(1, nb):
                for i in range(nb - dlt):
                    coupled[dlt, g.frames.first + i] = True
        self._maps = []
        for dlt in range(self.D + 1):
            other = dofs[np.minimum(np.arange(M) + dlt, M - 1)]
            r = np.repeat(dofs[:, :, None], 3 * kb, axis=2)
            c = np.repeat(other[:, None, :], 3 * kb, axis=1)
            keep = (r >= 0) & (c >= 0) & coupled[dlt][:, None, None]
            if dlt == 0:
                # a diagonal block: each entry once, where it lies in the upper triangle
                keep &= r <= c
                lo, hi = r[keep], c[keep]
                weight = None
            else:
                # a block off the diagonal stands for itself and its transpose: each entry
                # goes to the upper position of the pair, twice on the diagonal (a fabric node
                # in the stencils of both blocks)
                lo, hi = np.minimum(r, c)[keep], np.maximum(r, c)[keep]
                weight = np.where(r == c, 2.0, 1.0)[keep]
            pos = np.searchsorted(codes, hi * n + lo)
            if not np.array_equal(codes[np.minimum(pos, codes.size - 1)], hi * n + lo):
                raise ValueError("frames: a coupled pair of blocks is not in the pattern")
            self._maps.append((keep, pos, weight))
        self.positions = np.concatenate([m[1] for m in self._maps])

    # -------------------------------------------------------------- evaluation
    def _laid_params(self) -> list:
        key = tuple(id(g.params) for g in self.groups)
        if key != self._params_key:
            out = []
            for g in self.groups:
                first = g.frames.first
                laid = []
                for p in g.params:
                    a = np.repeat(p[:1], self.M, axis=0)  # any valid element's numbers
                    a[first] = p
                    laid.append(jax.device_put(a))
                out.append(laid)
            self._params, self._params_key = out, key
        return self._params

    def run(self, xj: jnp.ndarray, stresses: Sequence[np.ndarray]
            ) -> tuple[np.ndarray, np.ndarray]:
        """(gradient (n_nodes, 3) of the groups, Hessian values at :attr:`positions`) at
        ``xj``, with element stresses ``stresses[t]`` (n_el, m) of group t in the geometric
        term."""
        args = []
        for g, valid, par, s in zip(self.groups, self._valid, self._laid_params(), stresses,
                                    strict=True):
            sl = np.zeros((self.M,) + np.shape(s)[1:])
            sl[g.frames.first] = s
            args += [valid, *par, jax.device_put(sl)]
        out = self._kernel(xj, self._nodes, self._fill, *args)
        g_nodes = np.asarray(out[0])
        vals = []
        for (keep, _, weight), Hd in zip(self._maps, out[1:], strict=True):
            v = np.asarray(Hd)[keep]
            vals.append(v if weight is None else v * weight)
        n_nodes = xj.shape[0]
        flat = self.layout.nodes.ravel()
        ge = g_nodes.reshape(-1, 3)
        grad = np.stack([np.bincount(flat, weights=ge[:, c], minlength=n_nodes)
                         for c in range(3)], axis=1)
        return grad, np.concatenate(vals)


def fused_frame_sets(asm) -> list[FusedFrames]:
    """One :class:`FusedFrames` per frame layout that strain-form groups of ``asm`` share
    (groups without ``frames`` are assembled element by element)."""
    from .forms import strain_form

    sets: dict[int, list[int]] = {}
    for i, g in enumerate(asm.groups):
        if getattr(g, "frames", None) is not None and strain_form(g.fn) is not None:
            sets.setdefault(id(g.frames.layout), []).append(i)
    return [FusedFrames(asm, idx) for idx in sets.values()]
