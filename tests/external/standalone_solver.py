#!/usr/bin/env python3
"""A standalone external solver for contactbench: numpy and json only, nothing from the project.

    python standalone_solver.py PROBLEM_DIR SOLUTION_DIR [--kernel] [--variant NAME]

It follows the file protocol contactbench-qp/1 (docs/external-solvers.md): it reads
problem.json and the raw little-endian arrays, and writes p.f64 and solution.json; it stops
at problem.json's ``max_iter`` when one is given, reporting status "max_iter".

Method: when the dense H is present (and ``--kernel`` is not given), block principal pivoting (Judice & Pires 1994) on
the LCP w = Hp - ubar >= 0, p >= 0, w'p = 0 -- finite for an SPD H.  Otherwise the
Polonsky-Keer constrained conjugate gradient on the FFT operator it builds itself from
kernel_table and index (H[a, b] = K[(i_a - i_b) mod P1, (j_a - j_b) mod P2]).

``--variant`` makes it misbehave on purpose (the tests catch each one): ``clip`` (one
unconstrained solve, negative p set to 0, status converged), ``sleep`` (sleeps past any
limit), ``segv`` (kills itself with SIGSEGV), ``fail`` (exits 3 after a message on
stderr), ``short`` (writes p one entry short), ``nan`` (writes a NaN into p).
"""

import json
import os
import signal
import sys
import time

import numpy as np


def read_problem(d):
    with open(os.path.join(d, "problem.json")) as fh:
        doc = json.load(fh)
    arrays = {}
    for name, a in doc["arrays"].items():
        arrays[name] = np.fromfile(os.path.join(d, a["file"]), dtype=np.dtype(a["dtype"])).reshape(a["shape"])
    return doc, arrays


RELIEF_SHARE = 1e-6  # problems/kkt.py: the least share of ||ubar||_inf in the displacement scale
U_SCALE_FALLBACK = 1.0  # problems/kkt.py: the scale when that is 0 (ubar = 0)


def problem_scales(ubar, dmax):
    """The judge's (u_s, p_s) under displacement control (problems/kkt.py, problem_scales):
    u_s = max(max ubar, 1e-6 ||ubar||_inf), the approach -- U_SCALE_FALLBACK when that is 0
    or p_s would underflow -- and p_s = u_s / max diag H."""
    top = float(np.max(np.abs(ubar), initial=0.0))
    us = max(float(np.max(ubar, initial=0.0)), RELIEF_SHARE * top)
    if not (us > 0.0 and us / dmax > 0.0):
        us = U_SCALE_FALLBACK
    return us, us / dmax


def scaled_kkt(p, w, ubar, dmax):
    us, ps = problem_scales(ubar, dmax)  # the problem's scales, the judge's (problems/kkt.py)
    primal = max(0.0, -float(np.min(p, initial=0.0))) / ps
    dual = max(0.0, -float(np.min(w, initial=0.0))) / us
    comp = float(np.max(np.abs(w * p), initial=0.0)) / (us * ps)
    return max(primal, dual, comp)


def bpp(H, ubar, max_iter=1000):
    """Block principal pivoting with Murty's single-index fallback: (p, iterations, status)."""
    n = ubar.size
    F = np.zeros(n, dtype=bool)  # the free set: p > 0 there, w = 0
    best, backup = n + 1, 3
    p = np.zeros(n)
    for it in range(1, max_iter + 1):
        p = np.zeros(n)
        if F.any():
            p[F] = np.linalg.solve(H[np.ix_(F, F)], ubar[F])
        w = H @ p - ubar
        bad = (F & (p < 0)) | (~F & (w < -1e-14 * max(1.0, np.max(np.abs(ubar)))))
        k = int(np.count_nonzero(bad))
        if k == 0:
            return np.maximum(p, 0.0), it, "converged"
        if k < best:
            best, backup = k, 3
            F ^= bad
        elif backup > 0:
            backup -= 1
            F ^= bad
        else:
            j = int(np.flatnonzero(bad).max())
            F[j] = not F[j]
    return np.maximum(p, 0.0), max_iter, "max_iter"


class FFTOperator:
    def __init__(self, table, grid, index):
        self.P = table.shape
        self.grid = grid
        self.i, self.j = index[:, 0], index[:, 1]
        self.khat = np.fft.rfft2(table)

    def __call__(self, x):
        f = np.zeros(self.P)
        f[self.i, self.j] = x
        return np.fft.irfft2(np.fft.rfft2(f) * self.khat, s=self.P)[self.i, self.j]


def polonsky_keer(Hmul, ubar, dmax, tol, deadline, max_iter=20000):
    """Constrained CG on p >= 0 (Polonsky & Keer 1999, with the far-field displacement
    fixed, so the gap's mean is not removed)."""
    n = ubar.size
    p = np.maximum(ubar, 0.0) / dmax  # a positive start on the rigid-body overlap
    t = np.zeros(n)
    G_old, delta = 1.0, 0.0
    for it in range(1, max_iter + 1):
        g = Hmul(p) - ubar
        if scaled_kkt(p, g, ubar, dmax) <= tol:
            return p, it, "converged"
        if time.perf_counter() > deadline:
            return p, it, "time_limit"
        S = p > 0
        G = float(g[S] @ g[S])
        t = np.where(S, g + (delta * G / G_old) * t, 0.0)
        G_old = G
        r = Hmul(t)
        rt = float(r[S] @ t[S])
        tau = float(g[S] @ t[S]) / rt if rt > 0 else 0.0
        p = np.maximum(p - tau * t, 0.0)
        overlap = (p == 0) & (g < 0)  # gaps closed below zero: enter the contact set
        p[overlap] -= tau * g[overlap]
        delta = 0.0 if overlap.any() else 1.0
    return p, max_iter, "max_iter"


def main(argv):
    pdir, sdir = argv[1], argv[2]
    variant = argv[argv.index("--variant") + 1] if "--variant" in argv else ""
    t0 = time.perf_counter()
    doc, a = read_problem(pdir)
    n, ubar = int(doc["n"]), a["ubar"].astype(np.float64)
    tol = doc.get("tol") or 1e-8
    limit = doc.get("time_limit") or 3600.0
    max_iter = doc.get("max_iter")  # the harness's iteration limit (null: keep our own)
    own = {} if max_iter is None else {"max_iter": int(max_iter)}
    status = "converged"
    if variant == "sleep":
        time.sleep(limit + 600.0)
    if variant == "segv":
        os.kill(os.getpid(), signal.SIGSEGV)
    if variant == "fail":
        print("standalone_solver: giving up on purpose", file=sys.stderr)
        return 3
    if "H" in a and "--kernel" not in argv:
        H = a["H"]
        dmax = float(np.max(np.diag(H)))
        if variant == "clip":
            p, it = np.maximum(np.linalg.solve(H, ubar), 0.0), 1
        else:
            p, it, status = bpp(H, ubar, **own)
    else:
        op = FFTOperator(a["kernel_table"], doc["grid"], a["index"])
        dmax = float(a["kernel_table"][0, 0])
        p, it, status = polonsky_keer(op, ubar, dmax, tol, t0 + 0.9 * limit, **own)
    if variant == "short":
        p = p[:-1]
    if variant == "nan":
        p = p.copy()
        p[0] = np.nan
    np.ascontiguousarray(p, dtype="<f8").tofile(os.path.join(sdir, "p.f64"))
    with open(os.path.join(sdir, "solution.json"), "w") as fh:
        json.dump({"iterations": int(it), "status": status, "time_s": time.perf_counter() - t0}, fh)
    print(f"standalone_solver: n = {n}, {it} iterations, {status}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
