"""Dense strictly convex QP with inequality constraints, solved by a compiled dual active-set
method (Goldfarb & Idnani, 1983).

    minimize 1/2 z' H z + g' z   subject to   C z >= b   (row by row)

``H`` must be symmetric positive definite (the condensed MPC Hessian is). The method starts
at the unconstrained minimum ``-H^{-1} g`` and adds the most violated constraint one at a
time, dropping constraints whose multiplier would turn negative; every iterate is optimal for
the constraints added so far, so an MPC step whose constraints are all inactive costs one
Cholesky factorization and two triangular solves. Factorizations are kept in the orthogonal
form ``J = L^{-T} Q``, ``J' N_A = [R; 0]`` (O(n^2) per change of the active set): ``J`` is
stored transposed, so that every update reads and writes contiguous rows. Adding a constraint
applies one Householder reflection to the free part of ``J'``: a rank-one update of
n (n - q) multiply-adds for q active constraints, built from the primal search direction
already at hand, a quarter of the multiplications of a sequence of Givens rotations. Dropping
one restores ``R``'s triangle with Givens rotations.

Rows with a single nonzero (input bounds, slack signs) are named by the caller (``rowcol``):
their value ``c z_j - b`` costs O(1) in the scan for the most violated row, and their search
direction ``J' n = c J'[:, j]`` O(n) instead of a matrix-vector product. The other rows are
read only where they may be nonzero (``rowspan``: leading columns and one more): a condensed MPC
row at stage k reaches the inputs before it and a slack, so the scan for the most violated row
and the search directions of a heavy solve cost about half (a solve of 800 active-set changes:
4.9 -> 4.1 ms).

Everything here is compiled with numba (``cache=True``: a new process loads the machine code
from the cache instead of recompiling) and works in caller-provided buffers: nothing is
allocated per solve. :class:`DenseQpSolver` wraps the kernel for use from Python (tests,
experiments); the controller calls :func:`gi_solve` from its own compiled step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._subroutine import subroutine

#: status codes of :func:`gi_solve` (mapped to the status words of ``mpcdrive.types``)
QP_OK = 0
QP_INFEASIBLE = 1
QP_MAX_ITER = 2
QP_FAILED = 3  # H not positive definite, or non-finite data

STATUS_WORDS = ("ok", "infeasible", "max_iter", "failed")

# reassociation lets LLVM vectorize the dot products; no 'nnan' / 'ninf', so non-finite data is
# still detected
_FM = {"reassoc", "contract"}


@subroutine(fastmath=_FM)
def cholesky_lower(H, L, n) -> bool:
    """L (lower triangle of the n x n leading block) with H = L L'; False if H is not
    numerically positive definite. Only the lower triangle of H is read."""
    for j in range(n):
        s = H[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not (s > 1e-14 * max(1.0, abs(H[j, j]))):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        inv = 1.0 / d
        for i in range(j + 1, n):
            t = H[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t * inv
    return True


@subroutine(fastmath=_FM)
def _unconstrained(L, g, z, n):
    """z = -H^{-1} g from the Cholesky factor L (forward then backward substitution)."""
    for i in range(n):
        t = -g[i]
        for k in range(i):
            t -= L[i, k] * z[k]
        z[i] = t / L[i, i]
    for i in range(n - 1, -1, -1):
        t = z[i]
        for k in range(i + 1, n):
            t -= L[k, i] * z[k]
        z[i] = t / L[i, i]


@subroutine(fastmath=_FM)
def _inverse_lower(L, Jt, n):
    """Jt = L^{-1} (lower triangular), row by row: row i is (e_i - sum_{l<i} L[i, l] row l) / L[i, i].
    This is J' for the initial ``J = L^{-T}``."""
    for i in range(n):
        for k in range(n):
            Jt[i, k] = 0.0
        for l in range(i):
            a = L[i, l]
            if a != 0.0:
                for k in range(l + 1):
                    Jt[i, k] -= a * Jt[l, k]
        inv = 1.0 / L[i, i]
        for k in range(i):
            Jt[i, k] *= inv
        Jt[i, i] = inv


@subroutine(fastmath=_FM)
def _givens(a, b):
    h = math.hypot(a, b)
    if h == 0.0:
        return 1.0, 0.0, 0.0
    return a / h, b / h, h


@subroutine
def _span(rowspan, i, n):
    """(the leading columns to read, the one more column or -1) of row ``i`` read whole, within
    ``n`` columns (a ``rowspan`` of :func:`gi_solve`: the more column counts only past the lead)."""
    e = min(rowspan[i, 0], n)
    jx = rowspan[i, 1]
    return e, (jx if e <= jx < n else -1)


@subroutine(fastmath=_FM)
def gi_solve(
    H, g, C, b, m, n, z, lam, active, isact, rowcol, rowspan, L, Jt, R, d, zdir, r, u, s, rownorm, max_iter, tol
):
    """Solve ``min 1/2 z'Hz + g'z  s.t.  C[:m, :n] z >= b[:m]``; returns (status, iterations).

    H : (>=n, >=n) SPD (lower triangle read); g : (n,); C : (>=m, >=n); b : (m,);
    rowcol : (m,) int, the column of row i's only nonzero (a bound: its value, its product with
    z and the search direction cost O(1) / O(n) instead of O(n) / O(n^2)), or -1 where the row
    is to be read whole (always correct; :func:`single_nonzero_columns` computes it).
    rowspan : (m, 2) int, where a row read whole may be nonzero: its first ``rowspan[i, 0]``
    columns and the column ``rowspan[i, 1]`` (-1: none); ``(n, -1)`` is always correct
    (:func:`row_spans` computes the tightest). The rows of a condensed MPC problem at stage k
    reach only the inputs before it (and a slack): the dense products cost about half.
    Outputs: z : (n,) the solution; lam : (m,) multipliers (>= 0, zero for inactive rows);
    active : (n,) int, indices of the active rows (first ``q`` entries, q = number active).
    Work buffers: L, Jt, R (n x n), d, zdir, r, u (n,), s, rownorm (m,), isact (m,) int.
    tol : feasibility tolerance on the violation of a row scaled by its norm.
    isact on entry : a guess of the active set (1: active, e.g. the rows a similar QP ended
    with; all 0 for none): the most violated of those rows is added before any other row is,
    which rebuilds such an active set with few drops. Any order of adding violated rows leads
    to the same optimum (every iterate is dual feasible); the guess only saves iterations.
    On return ``isact`` marks the active rows (1) and the guessed rows never added (2).
    (The guess is data, not a flag: a constant flag would make the compiler build this solver
    once per value.)
    """
    if not cholesky_lower(H, L, n):
        return QP_FAILED, 0
    for i in range(n):
        if not math.isfinite(g[i]):
            return QP_FAILED, 0
    _unconstrained(L, g, z, n)
    for i in range(m):
        lam[i] = 0.0
        isact[i] = 2 if isact[i] == 1 else 0  # 2: guessed active, not yet added
        j1 = rowcol[i]
        if j1 >= 0:
            t = C[i, j1] * C[i, j1]
        else:
            t = 0.0
            e, jx = _span(rowspan, i, n)
            for j in range(e):
                t += C[i, j] * C[i, j]
            if jx >= 0:
                t += C[i, jx] * C[i, jx]
        rownorm[i] = math.sqrt(t)
        if not (math.isfinite(t) and math.isfinite(b[i])):
            return QP_FAILED, 0
        if t == 0.0 and b[i] > tol:  # 0 >= b[i] fails whatever z is
            return QP_INFEASIBLE, 0
    have_j = False
    q = 0
    it = 0
    while True:
        # -- step 1: the most violated constraint (scaled by its row norm), a guessed one first -
        p = -1
        worst = -tol
        pg = -1
        worst_g = -tol
        for i in range(m):
            if rownorm[i] == 0.0 or isact[i] == 1:
                continue
            j1 = rowcol[i]  # (inline: a helper taking the arrays is several times slower here)
            if j1 >= 0:
                t = C[i, j1] * z[j1] - b[i]
            else:
                t = 0.0
                e, jx = _span(rowspan, i, n)
                for j in range(e):
                    t += C[i, j] * z[j]
                if jx >= 0:
                    t += C[i, jx] * z[jx]
                t -= b[i]
            s[i] = t
            v = t / rownorm[i]
            if v < worst:
                worst = v
                p = i
            if isact[i] == 2 and v < worst_g:
                worst_g = v
                pg = i
        if pg >= 0:
            p = pg
        if p < 0:
            break
        if not have_j:
            _inverse_lower(L, Jt, n)
            have_j = True
        up = 0.0  # multiplier of the constraint being added
        sp = s[p]
        jp = rowcol[p]
        # -- step 2: move towards satisfying row p ----------------------------------------------
        while True:
            it += 1
            if it > max_iter:
                for k in range(q):
                    lam[active[k]] = u[k]
                return QP_MAX_ITER, it - 1
            # d = J' n_p (a column of J' for a row with a single nonzero)
            dd = 0.0
            if jp >= 0:
                cp = C[p, jp]
                for j in range(n):
                    t = cp * Jt[j, jp]
                    d[j] = t
                    dd += t * t
            else:
                ep, jx = _span(rowspan, p, n)
                for j in range(n):
                    t = 0.0
                    for i in range(ep):
                        t += Jt[j, i] * C[p, i]
                    if jx >= 0:
                        t += Jt[j, jx] * C[p, jx]
                    d[j] = t
                    dd += t * t
            # primal direction zdir = J2 d2, dual direction r = R^{-1} d1
            tail = 0.0  # |d[q+1:]|^2
            for i in range(n):
                zdir[i] = 0.0
            for j in range(q, n):
                dj = d[j]
                if dj != 0.0:
                    if j > q:
                        tail += dj * dj
                    for i in range(n):
                        zdir[i] += dj * Jt[j, i]
            d2 = d[q] * d[q] + tail if q < n else 0.0
            for k in range(q - 1, -1, -1):
                t = d[k]
                for l in range(k + 1, q):
                    t -= R[k, l] * r[l]
                r[k] = t / R[k, k]
            # step lengths: t1 (keep multipliers >= 0), t2 (make row p active)
            t1 = math.inf
            kdrop = -1
            for k in range(q):
                if r[k] > 0.0:
                    ratio = u[k] / r[k]
                    if ratio < t1:
                        t1 = ratio
                        kdrop = k
            if d2 <= 1e-14 * dd:
                t2 = math.inf
            else:
                t2 = -sp / d2
            tstep = min(t1, t2)
            if tstep == math.inf:
                for k in range(q):
                    lam[active[k]] = u[k]
                return QP_INFEASIBLE, it
            if t2 < math.inf:
                for i in range(n):
                    z[i] += tstep * zdir[i]
            for k in range(q):
                u[k] -= tstep * r[k]
            up += tstep
            if t2 <= t1:
                # full step: add p to the active set. A Householder reflection of rows q.. of J'
                # maps d[q:] onto (-sgn(d_q) sigma, 0, ..), sigma = |d[q:]|: with
                # v = d[q:] + sgn(d_q) sigma e_q (no cancellation) the rows change by
                # -(2 v_j / v'v) w, w = J2 v = zdir + sgn(d_q) sigma J'[q]; row q is then negated
                # where needed so that R keeps a positive diagonal
                sigma = math.sqrt(d2)
                dq = d[q]
                if q < n - 1:
                    sg = 1.0 if dq >= 0.0 else -1.0
                    vq = dq + sg * sigma
                    beta = 2.0 / (vq * vq + tail)
                    f = sg * sigma
                    for i in range(n):
                        zdir[i] += f * Jt[q, i]  # now w
                    f = beta * vq
                    for i in range(n):
                        Jt[q, i] = -sg * (Jt[q, i] - f * zdir[i])
                    for j in range(q + 1, n):
                        f = beta * d[j]
                        if f != 0.0:
                            for i in range(n):
                                Jt[j, i] -= f * zdir[i]
                elif dq < 0.0:
                    for i in range(n):
                        Jt[q, i] = -Jt[q, i]
                d[q] = sigma
                for k in range(q + 1):
                    R[k, q] = d[k]
                active[q] = p
                isact[p] = 1
                u[q] = up
                q += 1
                break
            # partial step: drop active constraint kdrop, then retry row p
            isact[active[kdrop]] = 0
            for l in range(kdrop, q - 1):
                for k in range(q):
                    R[k, l] = R[k, l + 1]
                u[l] = u[l + 1]
                active[l] = active[l + 1]
            q -= 1
            for j in range(kdrop, q):
                c_, s_, h = _givens(R[j, j], R[j + 1, j])
                if h == 0.0:
                    continue
                for l in range(j, q):
                    a_ = R[j, l]
                    b_ = R[j + 1, l]
                    R[j, l] = c_ * a_ + s_ * b_
                    R[j + 1, l] = -s_ * a_ + c_ * b_
                R[j + 1, j] = 0.0
                for i in range(n):
                    a_ = Jt[j, i]
                    b_ = Jt[j + 1, i]
                    Jt[j, i] = c_ * a_ + s_ * b_
                    Jt[j + 1, i] = -s_ * a_ + c_ * b_
            if jp >= 0:
                sp = C[p, jp] * z[jp] - b[p]
            else:
                sp = 0.0
                ep, jx = _span(rowspan, p, n)
                for j in range(ep):
                    sp += C[p, j] * z[j]
                if jx >= 0:
                    sp += C[p, jx] * z[jx]
                sp -= b[p]
    for k in range(q):
        lam[active[k]] = u[k]
    for i in range(n):
        if not math.isfinite(z[i]):
            return QP_FAILED, it
    return QP_OK, it


def row_spans(C: np.ndarray) -> np.ndarray:
    """The ``rowspan`` argument of :func:`gi_solve` for the rows of ``C`` (m, n): each row's
    nonzeros as its leading columns up to the last nonzero, and no extra column."""
    nz = np.asarray(C) != 0.0
    n = nz.shape[1] if nz.ndim == 2 else 0
    last = np.where(nz.any(axis=1), n - np.argmax(nz[:, ::-1], axis=1), 0) if n else np.zeros(len(nz), int)
    return np.column_stack([last, np.full(len(nz), -1)]).astype(np.int64)


def single_nonzero_columns(C: np.ndarray) -> np.ndarray:
    """The ``rowcol`` argument of :func:`gi_solve` for the rows of ``C``: the column of each
    row's only nonzero, -1 for rows with none or several."""
    nz = np.asarray(C) != 0.0
    return np.where(nz.sum(axis=1) == 1, nz.argmax(axis=1), -1).astype(np.int64)


@dataclass(frozen=True)
class DenseQpResult:
    """Solution of a dense QP: status word, z (n,), multipliers lam (m,) of ``C z >= b``,
    objective ``1/2 z'Hz + g'z``, iterations (changes of the active set)."""

    status: str
    z: np.ndarray
    lam: np.ndarray
    objective: float
    iterations: int


class DenseQpSolver:
    """Python entry to :func:`gi_solve` for QPs of at most ``n_max`` variables and ``m_max``
    constraints (buffers allocated once here)."""

    def __init__(self, n_max: int, m_max: int, max_iter: int | None = None, tol: float = 1e-9):
        if n_max < 1 or m_max < 0:
            raise ValueError(f"n_max must be >= 1 and m_max >= 0, got {n_max}, {m_max}")
        self.n_max, self.m_max = int(n_max), int(m_max)
        self.max_iter = int(max_iter if max_iter is not None else 10 * (n_max + m_max) + 10)
        self.tol = float(tol)
        n, m = self.n_max, max(self.m_max, 1)
        self._L = np.zeros((n, n))
        self._J = np.zeros((n, n))
        self._R = np.zeros((n, n))
        self._vec = np.zeros((4, n))
        self._s = np.zeros(m)
        self._norm = np.zeros(m)
        self._active = np.zeros(n, dtype=np.int64)
        self._isact = np.zeros(m, dtype=np.int64)

    def solve(self, H, g, C=None, b=None, active_guess=None) -> DenseQpResult:
        """Solve ``min 1/2 z'Hz + g'z  s.t.  C z >= b``. ``active_guess``: indices of rows
        likely active at the optimum (e.g. those a similar QP ended with, ``lam > 0``): they
        are added first, which saves iterations when the guess is good and never changes the
        solution."""
        H = np.ascontiguousarray(H, dtype=float)
        g = np.ascontiguousarray(g, dtype=float)
        n = g.shape[0]
        if H.shape != (n, n):
            raise ValueError(f"H must be {n}x{n}, got {H.shape}")
        if C is None:
            C, b = np.zeros((0, n)), np.zeros(0)
        C = np.ascontiguousarray(C, dtype=float)
        b = np.ascontiguousarray(b, dtype=float)
        m = b.shape[0]
        if C.shape != (m, n):
            raise ValueError(f"C must be {m}x{n}, got {C.shape}")
        if n > self.n_max or m > self.m_max:
            raise ValueError(f"QP of {n} variables / {m} rows exceeds the solver's {self.n_max} / {self.m_max}")
        if C.shape[0] == 0:
            C = np.zeros((1, n))
            b = np.zeros(1)
        z = np.zeros(n)
        lam = np.zeros(max(m, 1))
        rowcol = single_nonzero_columns(C)
        rowspan = row_spans(C)
        self._isact[:] = 0
        if active_guess is not None:
            guess = np.asarray(active_guess, dtype=np.int64).ravel()
            if guess.size and (guess.min() < 0 or guess.max() >= m):
                raise ValueError(f"active_guess must index rows 0..{m - 1}")
            self._isact[guess] = 1
        v = self._vec
        code, it = gi_solve(
            H,
            g,
            C,
            b,
            m,
            n,
            z,
            lam,
            self._active,
            self._isact,
            rowcol,
            rowspan,
            self._L,
            self._J,
            self._R,
            v[0],
            v[1],
            v[2],
            v[3],
            self._s,
            self._norm,
            self.max_iter,
            self.tol,
        )
        obj = float(0.5 * z @ H @ z + g @ z) if code == QP_OK else float("nan")
        return DenseQpResult(STATUS_WORDS[code], z, lam[:m].copy(), obj, int(it))
