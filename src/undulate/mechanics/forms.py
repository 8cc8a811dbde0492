"""Per-element kernels: what the assembler calls for every element group.

An energy function is a pure JAX function of one element's node positions and parameters.
Its kernels (energy per element, gradient, Hessian, and for the rods' mixed formulation the
stresses and the merit's step terms) come from autodiff (``jax.grad``/``jax.hessian`` under
``jax.vmap``) or from a :class:`StrainForm` the function declares: energy = W(strains(q)),
whose chain rule gives exact Hessians cheaply. Kernels are compiled once and kept on disk
(:mod:`undulate.mechanics.compiled`) for undulate's own energies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from .compiled import CachedJit

jax.config.update("jax_enable_x64", True)

__all__ = ["GATHER_LAST", "StrainForm", "StrainTerm", "composite_kernels", "gathered_kernels",
           "kernels_for", "strain_form", "strain_form_kernels"]


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
    f = _FormKernels(sf)
    return {
        "per_element": jax.vmap(f.energy),
        "grad": jax.vmap(f.grad_one),
        "grad_hess": jax.vmap(f.grad_hess_one),
        "grad_hess_mixed": jax.vmap(f.grad_hess_mixed_one),
        "stress": jax.vmap(f.stress_one),
        "stress_lin": jax.vmap(f.stress_lin_one),
        "merit_step": jax.vmap(f.merit_step_one),
    }


class _FormKernels:
    """One element's kernels of a strain-form energy (vmapped by :func:`strain_form_kernels`);
    ``xl`` is the element's (k, 3) node positions, ``p`` its parameters."""

    def __init__(self, sf: StrainForm) -> None:
        self.sf = sf
        self.nb = sf.n_blocks

    def bf(self, y):
        return self.sf.block(y.reshape(-1, 3))

    def split(self, xl):
        return xl.reshape(self.nb, -1)

    def strains(self, xl, p):
        return self.sf.strains(jax.vmap(self.bf)(self.split(xl)).ravel(), *p)

    def energy(self, xl, *p):
        e = self.strains(xl, p)
        return 0.5 * jnp.sum(self.sf.moduli(*p) * e * e)

    def parts(self, xl, *p):
        sf, bf = self.sf, self.bf
        xb = self.split(xl)
        q = jax.vmap(bf)(xb)  # (nb, mq)
        Jq = jax.vmap(jax.jacfwd(bf))(xb)  # (nb, mq, 3kb)
        e = sf.strains(q.ravel(), *p)
        Je = sf.jacobian(q.ravel(), *p)  # (m, nb*mq)
        return xb, q, Jq, e, Je

    def grad_one(self, xl, *p):
        _, q, Jq, e, Je = self.parts(xl, *p)
        dq = ((self.sf.moduli(*p) * e) @ Je).reshape(q.shape)
        return jnp.einsum("bm,bmi->bi", dq, Jq).reshape(xl.shape)

    def grad_hess_with(self, xl, p, s):
        sf, nb = self.sf, self.nb
        xb, q, Jq, e, Je = self.parts(xl, *p)
        k = sf.moduli(*p)
        n_q = q.shape[1]
        g = jnp.einsum("bm,bmi->bi", ((k * e) @ Je).reshape(nb, n_q), Jq).reshape(xl.shape)
        s = k * e if s is None else s
        Hs = sf.weighted_hessian(q.ravel(), s, *p)
        Hq = (Je.T * k) @ Je + Hs
        Hq = Hq.reshape(nb, n_q, nb, n_q)
        dq = (s @ Je).reshape(nb, n_q)
        H = jnp.einsum("bmi,bmcn,cnj->bicj", Jq, Hq, Jq)
        H = H + jnp.einsum("bij,bc->bicj", _weighted_block_hessians(self.bf, xb, dq),
                           jnp.eye(nb))
        n = xl.size
        return g, H.reshape(n, n)

    def grad_hess_one(self, xl, *p):
        return self.grad_hess_with(xl, p, None)

    def grad_hess_mixed_one(self, xl, *args):
        return self.grad_hess_with(xl, args[:-1], args[-1])

    def stress_one(self, xl, *p):
        return self.sf.moduli(*p) * self.strains(xl, p)

    def linearized_strains(self, xl, p, dxl):
        e, de = jax.jvp(lambda y: self.strains(y, p), (xl,), (dxl,))
        return e + de

    def stress_lin_one(self, xl, *args):
        p, dxl = args[:-1], args[-1]
        return self.sf.moduli(*p) * self.linearized_strains(xl, p, dxl)

    def merit_step_one(self, xl, *args):
        # at xl + dxl: the energy, and the mixed merit s e - s^2 / (2 k) with s = k e_lin the
        # stress of the strains linearized at xl (= the energy less k (e - e_lin)^2 / 2);
        # then s itself (what stress_lin returns for this step: the stress a Newton iteration
        # carries on when the line search takes the step)
        p, dxl = args[:-1], args[-1]
        e_lin = self.linearized_strains(xl, p, dxl)
        e1 = self.strains(xl + dxl, p)
        k = self.sf.moduli(*p)
        return jnp.concatenate([
            jnp.stack([jnp.sum(k * e_lin * (e1 - 0.5 * e_lin)), 0.5 * jnp.sum(k * e1 * e1)]),
            k * e_lin])


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
