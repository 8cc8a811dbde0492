"""Sparse factorization candidates on the project's own Hessians (docs/benchmarks.md,
"Sparse factorization").

    # 1. generate the matrices (a few minutes; stops each simulation once it has them)
    PYTHONPATH=src python benchmarks/bench_linear.py gen five   --out /tmp/undulate-linear
    PYTHONPATH=src python benchmarks/bench_linear.py gen single --out /tmp/undulate-linear
    # 2. time every importable candidate, interleaved, against the yardstick
    PYTHONPATH=src python benchmarks/bench_linear.py bench --dir /tmp/undulate-linear
    # 3. inertia against dense eigvalsh on shifted principal submatrices
    PYTHONPATH=src python benchmarks/bench_linear.py inertia --dir /tmp/undulate-linear

Matrices are the UPPER triangle in CSC, as Assembly.gradient_hessian returns them:
``flat`` (printed flat state, positive definite), ``indef1`` (first Hessian with negative
eigenvalues, just past buckling), ``buckled`` (last stable equilibrium reached). Candidates
whose package is not installed are skipped: qdldl, pymetis (nested-dissection pre-ordering),
pypardiso (+ mkl), python-mumps (``mumps``), cholespy.
"""

from __future__ import annotations

import argparse
import faulthandler
import glob
import importlib.util
import os
import statistics
import sys
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla

CASES = {
    "five": {"name": "five", "rods": {"h": 0.4, "N": 5, "s": 10.0, "L": 100.0},
             "release": {"steps": 15}, "mesh": {"dx_rod": 1.0}},
    "single": {"fabric": {"margin_y": 100.0}, "rods": {"h": 0.3, "L": 100.0},
               "release": {"steps": 15}},
    # smaller Hessians for the size threshold of ``auto`` (flat state only: gen --flat-only)
    "default": {},
    "short": {"rods": {"L": 30.0}},
}


# ----------------------------------------------------------------------------- generation
def generate(name: str, out: str, steps_after: int = 4, flat_only: bool = False) -> None:
    """Run the case, save Hessians (upper CSC) seen by the Newton solver, stop early."""
    import undulate.solve.release as rel
    from undulate import api
    from undulate.mechanics.assemble import Assembly

    out = os.path.join(out, name)
    os.makedirs(out, exist_ok=True)
    st = dict(last=None, step=0, flat=False, indef=0, indef_step=None, last_pd=None)
    gh0, ms0, mn0 = Assembly.gradient_hessian, rel.make_solver, rel.minimize

    def gh(self, *a, **k):
        g, H = gh0(self, *a, **k)
        st["last"] = H
        return g, H

    class Enough(Exception):
        pass

    class Recorder:
        def __init__(self, inner):
            self.inner = inner
            self.name = inner.name

        def factor(self, H):
            n = self.inner.factor(H)
            if H is st["last"]:  # a Hessian, not a shifted K
                if n == 0 and not st["flat"]:
                    sp.save_npz(f"{out}/flat.npz", H)
                    st["flat"] = True
                    if flat_only:
                        raise Enough
                if n > 0 and st["indef"] == 0:
                    st["indef"], st["indef_step"] = 1, st["step"]
                    sp.save_npz(f"{out}/indef1.npz", H)
                    print(f"{name}: indefinite Hessian, {n} negative", flush=True)
                if n == 0:
                    st["last_pd"] = H
            return n

        def solve(self, b):
            return self.inner.solve(b)

    def mn(*a, **k):
        r = mn0(*a, **k)
        st["step"] += 1
        if st["indef"] and st["last_pd"] is not None:
            sp.save_npz(f"{out}/buckled.npz", st["last_pd"])
            if st["step"] >= st["indef_step"] + steps_after:
                raise Enough
        return r

    Assembly.gradient_hessian, rel.make_solver, rel.minimize = (
        gh, lambda *a, **k: Recorder(ms0(*a, **k)), mn)
    try:
        api.simulate(CASES[name])
    except Enough:
        pass
    finally:
        Assembly.gradient_hessian, rel.make_solver, rel.minimize = gh0, ms0, mn0
    print(f"{name}: saved {sorted(os.listdir(out))}")


# ----------------------------------------------------------------------------- candidates
def shifted(H, tau):
    """H + tau I with exactly H's pattern (sorted upper CSC with a full diagonal)."""
    K = H.copy()
    last = K.indptr[1:] - 1
    assert np.array_equal(K.indices[last], np.arange(K.shape[0])), "diagonal not stored"
    K.data[last] += tau
    return K


def full(H_upper):
    return (H_upper + sp.triu(H_upper, 1).T).tocsc()


class Qdldl:
    def __init__(self, perm=None, label="qdldl (AMD)"):
        self.name, self.perm = label, perm

    def _p(self, H):
        if self.perm is None:
            return H
        p = self.perm
        return sp.triu(full(H)[p][:, p]).tocsc()

    def setup(self, H):
        import qdldl

        self.s = qdldl.Solver(self._p(H), upper=True)
        return self._inertia()

    def refactor(self, H):
        self.s.update(self._p(H), upper=True)
        return self._inertia()

    def _inertia(self):
        return int(np.count_nonzero(self.s.factors()[1] < 0))

    def solve(self, b):
        if self.perm is None:
            return self.s.solve(b)
        x = np.empty_like(b)
        x[self.perm] = self.s.solve(b[self.perm])
        return x


class SuperLU:
    def __init__(self, permc="MMD_AT_PLUS_A", perm=None, label=None):
        self.permc, self.perm = permc, perm
        self.name = label or f"splu ({permc})"

    def setup(self, H):
        return self.refactor(H)

    def refactor(self, H):  # SuperLU has no refactorization: analysis every time
        A = full(H)
        if self.perm is not None:
            A = A[self.perm][:, self.perm].tocsc()
        self.lu = spla.splu(A, permc_spec=self.permc, diag_pivot_thresh=0.0,
                            options={"SymmetricMode": True})
        return int(np.count_nonzero(self.lu.U.diagonal() < 0))

    def solve(self, b):
        if self.perm is None:
            return self.lu.solve(b)
        x = np.empty_like(b)
        x[self.perm] = self.lu.solve(b[self.perm])
        return x


class Pardiso:
    """MKL PARDISO through pypardiso's ctypes handle: mtype -2 (real symmetric indefinite,
    Bunch-Kaufman), phase 11 once, phase 22 per refactorization, inertia iparm(22)/(23)."""

    def __init__(self, threads=None):
        self.threads = threads
        self.name = "pardiso (MKL)" + (f" {threads} thr" if threads else "")

    def _call(self, phase, A, b):
        import ctypes

        # ia/ja/a stay alive on self between phases (PARDISO may keep pointers to them)
        b = np.asfortranarray(b, dtype=float)
        x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        f64 = ctypes.POINTER(ctypes.c_double)
        ps = self.ps
        ps._mkl_pardiso(
            ps.pt.ctypes.data_as(ctypes.POINTER(ps._pt_type[0])), ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(-2)),
            ctypes.byref(ctypes.c_int32(phase)), ctypes.byref(ctypes.c_int32(A.shape[0])),
            A.data.ctypes.data_as(f64), self.ia.ctypes.data_as(i32),
            self.ja.ctypes.data_as(i32), ps.perm.ctypes.data_as(i32),
            ctypes.byref(ctypes.c_int32(b.shape[1])), ps.iparm.ctypes.data_as(i32),
            ctypes.byref(ctypes.c_int32(0)), b.ctypes.data_as(f64), x.ctypes.data_as(f64),
            ctypes.byref(err))
        if err.value != 0:
            raise RuntimeError(f"PARDISO error {err.value}")
        return x

    def setup(self, H):
        from pypardiso.pardiso_wrapper import PyPardisoSolver

        self.ps = PyPardisoSolver(mtype=-2)
        if self.threads:
            self.ps.libmkl.MKL_Set_Num_Threads(self.threads)
        self.ps.set_iparm(1, 1)   # non-default iparm
        self.ps.set_iparm(2, 2)   # METIS ordering
        self.ps.set_iparm(10, 8)  # pivot perturbation 1e-8
        self.ps.set_iparm(11, 0)  # no scaling (symmetric indefinite default)
        self.ps.set_iparm(13, 0)  # no weighted matching (default for -2)
        self.ps.set_iparm(21, 1)  # Bunch-Kaufman pivoting
        self.ps.set_iparm(35, 0)  # one-based indexing
        # CSC upper -> CSR upper (what PARDISO wants); the value permutation is kept
        idx = sp.csc_matrix((np.arange(H.nnz, dtype=float), H.indices, H.indptr), H.shape)
        idx = idx.tocsr()
        self.to_csr = idx.data.astype(np.int64)
        self.A = sp.csr_matrix((H.data[self.to_csr], idx.indices, idx.indptr), H.shape)
        self.ia = (self.A.indptr + 1).astype(np.int32)
        self.ja = (self.A.indices + 1).astype(np.int32)
        self._call(11, self.A, np.zeros((H.shape[0], 1)))
        return self.refactor(H)

    def refactor(self, H):
        self.A.data[:] = H.data[self.to_csr]
        self._call(22, self.A, np.zeros((H.shape[0], 1)))
        return int(self.ps.iparm[22])  # iparm(23): number of negative eigenvalues

    def solve(self, b):
        return self._call(33, self.A, np.asfortranarray(b.reshape(-1, 1))).ravel()


class Mumps:
    """python-mumps (``mumps``), sym=2: analysis once, factor per refactorization;
    inertia INFOG(12)."""

    name = "mumps (sym=2)"

    def setup(self, H):
        import mumps

        self.ctx = mumps.Context()
        self.ctx.set_matrix(H, symmetric=True)
        self.ctx.analyze()
        return self.refactor(H)

    def refactor(self, H):
        self.ctx.set_matrix(H, symmetric=True)
        self.ctx.factor(reuse_analysis=True)
        return int(self.ctx.mumps_instance.infog[12])

    def solve(self, b):
        return self.ctx.solve(b)


class Cholespy:
    """CHOLMOD-based Cholesky (SPD only); factors with analysis on construction."""

    name = "cholespy (SPD only)"

    def setup(self, H):
        return self.refactor(H)

    def refactor(self, H):
        from cholespy import CholeskySolverD, MatrixType

        A = full(H)
        self.n = A.shape[0]
        self.s = CholeskySolverD(self.n, A.indptr.astype(np.int32), A.indices.astype(np.int32),
                                 A.data, MatrixType.CSC)
        return 0

    def solve(self, b):
        x = np.zeros_like(b)
        self.s.solve(np.ascontiguousarray(b), x)
        return x


def metis_perm(H):
    import pymetis

    A = full(H).tocsr()
    A.setdiag(0)
    A.eliminate_zeros()
    perm, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(A.indptr, A.indices))
    return np.asarray(perm)


def candidates(H):
    c = []
    have = lambda m: importlib.util.find_spec(m) is not None  # noqa: E731
    if have("qdldl"):
        c.append(Qdldl())
        rcm = csgraph.reverse_cuthill_mckee(full(H).tocsr(), symmetric_mode=True)
        c.append(Qdldl(np.asarray(rcm), "qdldl (RCM pre-perm)"))
        if have("pymetis"):
            c.append(Qdldl(metis_perm(H), "qdldl (METIS ND pre-perm)"))
    c.append(SuperLU("MMD_AT_PLUS_A"))
    c.append(SuperLU("COLAMD"))
    if have("pymetis"):
        c.append(SuperLU("NATURAL", metis_perm(H), "splu (METIS ND, NATURAL)"))
    if have("pypardiso"):
        c.append(Pardiso())  # MKL's thread count is global: set it with MKL_NUM_THREADS
    if have("mumps"):
        c.append(Mumps())
    if have("cholespy"):
        c.append(Cholespy())
    return c


def yardstick(path):
    spec = importlib.util.spec_from_file_location("yardstick", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.yardstick()


def bench(args):
    files = sorted(glob.glob(os.path.join(args.dir, args.cases, "*.npz")))
    rows = []
    ys = [yardstick(args.yardstick)]
    print(f"yardstick {ys[0]:.3f} s", flush=True)
    for f in files:
        H = sp.load_npz(f).tocsc()
        H.sort_indices()
        n = H.shape[0]
        tag = f"{os.path.basename(os.path.dirname(f))}/{os.path.basename(f)[:-4]}"
        d = H.diagonal()
        K = shifted(H, 1e-3 * np.abs(d).max())  # same pattern, other values
        rng = np.random.default_rng(0)
        b = rng.standard_normal(n)
        Hs = full(H)
        cands, setup_t, res = [], {}, {}
        for c in candidates(H):
            t0 = time.perf_counter()
            try:
                nneg = c.setup(H)
            except Exception as e:  # noqa: BLE001
                print(f"{tag:20s} {c.name:28s} setup failed: {type(e).__name__}: {e}")
                continue
            setup_t[c.name] = time.perf_counter() - t0
            x = c.solve(b)
            res[c.name] = (nneg, np.linalg.norm(Hs @ x - b) / np.linalg.norm(b))
            cands.append(c)
        tf = {c.name: [] for c in cands}
        ts = {c.name: [] for c in cands}
        for r in range(args.repeats):  # interleaved: every candidate once per round
            for c in cands:
                M = K if r % 2 else H
                t0 = time.perf_counter()
                try:
                    c.refactor(M)
                except Exception:  # noqa: BLE001
                    tf[c.name].append(float("nan"))
                    continue
                tf[c.name].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                for _ in range(3):
                    c.solve(b)
                ts[c.name].append((time.perf_counter() - t0) / 3)
        ys.append(yardstick(args.yardstick))
        for c in cands:
            nneg, rr = res[c.name]
            rows.append((tag, n, H.nnz, c.name, setup_t[c.name],
                         statistics.median(tf[c.name]), statistics.median(ts[c.name]),
                         nneg, rr))
            print(f"{tag:20s} n={n} {c.name:28s} setup {1e3 * setup_t[c.name]:8.1f} ms "
                  f"refactor {1e3 * rows[-1][5]:8.1f} ms solve {1e3 * rows[-1][6]:7.2f} ms "
                  f"n_neg {nneg:4d} resid {rr:.1e}", flush=True)
    y = statistics.median(ys)
    print(f"\nyardstick median {y:.3f} s over {len(ys)} runs: {[round(v, 3) for v in ys]}")
    print("| matrix | n | candidate | analysis+factor ms | refactor ms | solve ms | "
          "refactor / qdldl | refactor / splu | refactor / yardstick | n_neg | residual |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for tag, n, _nnz, name, s, f, so, nneg, rr in rows:
        q = next(r[5] for r in rows if r[0] == tag and r[3] == "qdldl (AMD)")
        u = next(r[5] for r in rows if r[0] == tag and r[3] == "splu (MMD_AT_PLUS_A)")
        print(f"| {tag} | {n} | {name} | {1e3 * s:.0f} | {1e3 * f:.1f} | {1e3 * so:.2f} | "
              f"{f / q:.2f} | {f / u:.2f} | {f / y:.3f} | {nneg} | {rr:.0e} |")


def inertia(args):
    """n_neg of every candidate vs dense eigvalsh on shifted principal submatrices."""
    for f in sorted(glob.glob(os.path.join(args.dir, "*", "*.npz"))):
        H = sp.load_npz(f).tocsc()
        m = min(args.sub, H.shape[0])
        S = sp.triu(full(H)[:m, :m]).tocsc()
        ev = np.linalg.eigvalsh(full(S).toarray())
        for k in (0, 5, 37):  # shift so that k eigenvalues are negative
            sigma = 0.0 if k == 0 else 0.5 * (ev[k - 1] + ev[k])
            if k == 0 and ev[0] <= 0:
                continue
            Sk = sp.triu(S - sigma * sp.eye(m)).tocsc()
            Sk.sort_indices()
            true = int(np.count_nonzero(ev - sigma < 0))
            got = {}
            for c in candidates(Sk):
                try:
                    got[c.name] = c.setup(Sk)
                except Exception as e:  # noqa: BLE001
                    got[c.name] = f"fail ({type(e).__name__})"
            print(f"{f} sub {m} shift {sigma:.3g}: eigvalsh {true}; {got}", flush=True)


def main():
    faulthandler.enable()
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("gen")
    g.add_argument("case", choices=sorted(CASES))
    g.add_argument("--out", default="/tmp/undulate-linear")
    g.add_argument("--flat-only", action="store_true")
    b = sub.add_parser("bench")
    b.add_argument("--dir", default="/tmp/undulate-linear")
    b.add_argument("--repeats", type=int, default=7)
    b.add_argument("--cases", default="*", help="glob of the case folders to time")
    b.add_argument("--yardstick", default=os.path.join(
        os.path.dirname(__file__), "..", "..", "shared", "yardstick.py"))
    i = sub.add_parser("inertia")
    i.add_argument("--dir", default="/tmp/undulate-linear")
    i.add_argument("--sub", type=int, default=2000)
    a = p.parse_args()
    if a.cmd == "gen":
        generate(a.case, a.out, flat_only=a.flat_only)
    elif a.cmd == "bench":
        if not os.path.exists(a.yardstick):
            a.yardstick = "/work/shared/yardstick.py"
        bench(a)
    else:
        inertia(a)


if __name__ == "__main__":
    sys.exit(main())
