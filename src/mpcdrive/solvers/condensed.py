"""Compiled solve pieces of the condensed MPC QP, beyond the dense active-set kernel.

The controller (:mod:`mpcdrive.control.compiled_step`) builds, each step, the stage data of a
linear-quadratic problem -- dynamics ``x_{k+1} = A_k x_k + B_k u_k + c_k``, state cost
``x' W_k x - 2 q_k' x``, input cost ``(u - u_ref)' R (u - u_ref)`` -- and its condensed form
onto the inputs (and slacks): ``minimize 1/2 z' H z + g' z  subject to  C z >= b``. The
functions here only consume that data; none knows a model, a path or how the rows were made.

* :func:`riccati`: the unconstrained minimizer of the stage problem (no input-rate cost, no
  slack) by the backward Riccati recursion, O(N); with :func:`plan_feasible` (input, rate and
  state bounds within a tolerance) the controller takes it as the QP's solution when it
  violates no bound, and skips condensing.
* :func:`condensed_solve`: the whole solve of one step's stage QP -- the Riccati shortcut where
  it applies, else condensing (Hessian by the backward recursion, gradient, state, road and
  obstacle rows) and :func:`soft_solve` or the plain active-set solve.
* :func:`soft_solve`: the condensed QP whose soft rows (grouped, one slack per group) get
  slacks only where they can be nonzero, by the exact-penalty condition on the multipliers of
  :func:`~mpcdrive.solvers.dense_qp.gi_solve`.

Compiled with numba (``cache=True``), working in caller-provided buffers: nothing is allocated
per solve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .._subroutine import subroutine
from .._structs import define_struct, to_struct
from .dense_qp import gi_solve


@subroutine
def riccati(N, nx, nu, A, B, c, qt, uref, Wq, Rm, x, P, p, K, kf, PA, M, G, q, z):
    """:func:`_riccati`; the sizes of the kinematic vehicle models (3 states / 1 input, 4 / 2)
    are handed on as constants, so the compiler unrolls the small matrix loops."""
    if nx == 3 and nu == 1:
        return _riccati(N, 3, 1, A, B, c, qt, uref, Wq, Rm, x, P, p, K, kf, PA, M, G, q, z)
    if nx == 4 and nu == 2:
        return _riccati(N, 4, 2, A, B, c, qt, uref, Wq, Rm, x, P, p, K, kf, PA, M, G, q, z)
    return _riccati(N, nx, nu, A, B, c, qt, uref, Wq, Rm, x, P, p, K, kf, PA, M, G, q, z)


@subroutine
def _riccati(N, nx, nu, A, B, c, qt, uref, Wq, Rm, x, P, p, K, kf, PA, M, G, q, z):
    """Unconstrained minimizer of the tracking cost (no Rc, no slack) by the backward Riccati
    recursion ``V_k(x) = x'P_k x + 2 p_k'x + const``, ``u_k = K_k x_k + kf_k``: O(N) work.
    The state cost of x_k is ``x' Wq[k-1] x - 2 qt[k-1]' x``.

    Scratch: PA (nx, nx), M (nu, nx), G (nu, nu), q (nx,). Writes z[:N nu] = U of the minimizer
    (rolled out from x) and uses p[1:] for the rolled-out states. Returns False if some
    ``R + B'PB`` is not numerically positive definite."""
    for i in range(nx):
        for j in range(nx):
            P[N, i, j] = Wq[N - 1, i, j]
        p[N, i] = -qt[N - 1, i]
    for k in range(N - 1, -1, -1):
        # q = P c + p ; PA = P A ; M = B'PA ; G = R + B'PB ; h = B'q - R ur (in kf[k])
        for i in range(nx):
            t = p[k + 1, i]
            for j in range(nx):
                t += P[k + 1, i, j] * c[k, j]
            q[i] = t
        for i in range(nx):
            for j in range(nx):
                t = 0.0
                for l in range(nx):
                    t += P[k + 1, i, l] * A[k, l, j]
                PA[i, j] = t
        for a in range(nu):
            for j in range(nx):
                t = 0.0
                for l in range(nx):
                    t += B[k, l, a] * PA[l, j]
                M[a, j] = t
            for e in range(nu):
                t = Rm[a, e]
                for l in range(nx):
                    pb = 0.0
                    for m_ in range(nx):
                        pb += P[k + 1, l, m_] * B[k, m_, e]
                    t += B[k, l, a] * pb
                G[a, e] = t
            t = 0.0
            for l in range(nx):
                t += B[k, l, a] * q[l]
            for e in range(nu):
                t -= Rm[a, e] * uref[k, e]
            kf[k, a] = t
        # G = L L' (in place, lower); K = -G^{-1} M ; kf = -G^{-1} h
        for j in range(nu):
            t = G[j, j]
            for l in range(j):
                t -= G[j, l] * G[j, l]
            if not (t > 1e-14 * max(1.0, abs(G[j, j]))):
                return False
            G[j, j] = math.sqrt(t)
            for i in range(j + 1, nu):
                t = G[i, j]
                for l in range(j):
                    t -= G[i, l] * G[j, l]
                G[i, j] = t / G[j, j]
        for col in range(nx + 1):
            for a in range(nu):
                q_a = M[a, col] if col < nx else kf[k, a]
                for l in range(a):
                    q_a -= G[a, l] * (K[k, l, col] if col < nx else kf[k, l])
                if col < nx:
                    K[k, a, col] = q_a / G[a, a]
                else:
                    kf[k, a] = q_a / G[a, a]
            for a in range(nu - 1, -1, -1):
                t = K[k, a, col] if col < nx else kf[k, a]
                for l in range(a + 1, nu):
                    t -= G[l, a] * (K[k, l, col] if col < nx else kf[k, l])
                if col < nx:
                    K[k, a, col] = t / G[a, a]
                else:
                    kf[k, a] = t / G[a, a]
        for a in range(nu):
            for col in range(nx):
                K[k, a, col] = -K[k, a, col]
            kf[k, a] = -kf[k, a]
        if k >= 1:
            # P_k = W_k + A'PA + M'K ; p_k = -W_k r_k + A'q + M'kf
            for i in range(nx):
                t = -qt[k - 1, i]
                for l in range(nx):
                    t += A[k, l, i] * q[l]
                for a in range(nu):
                    t += M[a, i] * kf[k, a]
                p[k, i] = t
                for j in range(nx):
                    t = Wq[k - 1, i, j]
                    for l in range(nx):
                        t += A[k, l, i] * PA[l, j]
                    for a in range(nu):
                        t += M[a, i] * K[k, a, j]
                    P[k, i, j] = t
    # roll out u_k = K_k x_k + kf_k from x (states staged in p[k + 1])
    for k in range(N):
        for a in range(nu):
            t = kf[k, a]
            for j in range(nx):
                t += K[k, a, j] * (x[j] if k == 0 else p[k, j])
            z[k * nu + a] = t
        for i in range(nx):
            t = c[k, i]
            for j in range(nx):
                t += A[k, i, j] * (x[j] if k == 0 else p[k, j])
            for a in range(nu):
                t += B[k, i, a] * z[k * nu + a]
            q[i] = t
        for i in range(nx):
            p[k + 1, i] = q[i]
    return True


@subroutine
def plan_feasible(N, nx, nu, z, Xr, u_prev, u_lo, u_hi, dmax, x_min, x_max, tol):
    """Whether inputs z (N nu) and states Xr[1..N] satisfy the per-stage input bounds u_lo,
    u_hi (N, nu), the rate and the state bounds within tol (NaN never does)."""
    for k in range(N):
        for a in range(nu):
            u = z[k * nu + a]
            if not (u >= u_lo[k, a] - tol and u <= u_hi[k, a] + tol):
                return False
            prev = u_prev[a] if k == 0 else z[(k - 1) * nu + a]
            if not (abs(u - prev) <= dmax[a] + tol):
                return False
        for i in range(nx):
            v = Xr[k + 1, i]
            if not (v >= x_min[i] - tol and v <= x_max[i] + tol):
                return False
    return True


@subroutine
def _group_excess(lam, m_soft, m, rgrp, N, w1l, w1o, gsum, kpos, every) -> bool:
    """Flag every slack group (``every``; else every group without a slack, kpos 0: flagged 2)
    whose rows' multipliers sum to more than its slack's l1 weight; True if none does (zero
    slacks are then optimal there)."""
    for grp in range(2 * N):
        gsum[grp] = 0.0
    for rr in range(m_soft, m):
        gsum[rgrp[rr]] += lam[rr]
    done = True
    for grp in range(2 * N):
        if (every or kpos[grp] == 0) and gsum[grp] > (w1l if grp < N else w1o):
            kpos[grp] = 1 if every else 2
            done = False
    return done


@subroutine
def _flag_later_groups(kpos, m_soft, m, rgrp, N, gsum):
    """After :func:`_group_excess` flagged groups (kpos = 2) that had no slack: flag every group
    with rows that follows one of them in its half (lane groups 0..N-1, obstacle groups
    N..2N-1). A row that needs a slack at step k mostly does at the steps after it too (the
    obstacle is still there); a slack too many costs a variable (it stays zero), one too few
    another solve. ``gsum`` (2N) is work space."""
    for grp in range(2 * N):
        gsum[grp] = 0.0
    for rr in range(m_soft, m):
        gsum[rgrp[rr]] = 1.0  # the group has rows
    for f0 in range(0, 2 * N, N):
        spread = False
        for k in range(N):
            grp = f0 + k
            spread = spread or kpos[grp] == 2
            if spread and gsum[grp] != 0.0:
                kpos[grp] = 1


@subroutine
def soft_solve(
    H,
    g,
    C,
    b,
    m,
    m_soft,
    rgrp,
    N,
    nzu,
    kpos,
    w2l,
    w1l,
    w2o,
    w1o,
    gsum,
    z,
    lam,
    active,
    isact,
    rowcol,
    rowspan,
    L,
    J,
    Rq,
    d,
    zdir,
    r,
    uq,
    sq,
    rown,
    max_iter,
    tol,
    soft,
    kprev,
):
    """The condensed QP with soft rows, their slacks only where they can be nonzero.

    ``H[:nzu, :nzu]``, ``g[:nzu]`` are the input part; rows ``[0, m)`` of ``C z >= b`` the
    constraints, of which rows ``[m_soft, m)`` are soft: row ``rr`` belongs to slack group
    ``rgrp[rr]`` (the lane rows of step k to group k, slack weights ``w2l`` quadratic, ``w1l``
    linear; the obstacle rows of step k to group N + k, weights ``w2o``, ``w1o``), one slack per
    group shared by its rows, as in ``ocp.qp``. Without soft rows (``m_soft == m``) that is one
    solve of the hard QP. First the inputs alone, soft rows hard: if that solves and no group's
    multipliers sum to more than its slack's l1 weight, zero slacks satisfy the optimality
    conditions of the soft problem (exact penalty), so it is its solution. Else slacks are given
    to the groups flagged in ``kpos`` (1 = slack; the caller flags those the linearization
    violates) and every group whose multipliers exceed the weight, each with the groups with rows
    after it (:func:`_flag_later_groups`), and solved again until no group without a slack
    exceeds it (or with a slack on every group that has rows: the full problem). The slacks' sign
    rows follow row m (``rowcol`` names their single nonzero; the other rows written per step are
    marked dense there, and ``rowspan`` gets each soft row's slack column). z[:nzu] holds the
    inputs.
    ``soft``: there may be soft rows; a constant False leaves the code of the slacks out (then
    ``m_soft`` must be ``m``). ``kprev`` (2N): the groups that had a slack in the last solve
    that needed slacks (:func:`shift_soft_guess` moves them on a step each control step); when
    this one needs slacks, those groups are flagged with the others from the first round (a
    guess: a slack that stays zero costs a variable, a missing one a round; the rounds end as
    before, when no group without a slack needs one, at the same solution), and ``kprev`` then
    holds this solve's groups."""
    for i in range(m):
        isact[i] = 0  # no guess of the active set
    code, iters = gi_solve(
        H, g, C, b, m, nzu, z, lam, active, isact, rowcol, rowspan, L, J, Rq, d, zdir, r, uq, sq, rown, max_iter, tol
    )
    if not soft or m_soft == m:  # no soft rows: the QP is that one
        return code, iters
    if code == 0 and _group_excess(lam, m_soft, m, rgrp, N, w1l, w1o, gsum, kpos, True):
        return 0, iters
    for grp in range(2 * N):  # the groups that had a slack in the solve before: a guess
        if kprev[grp] != 0:
            kpos[grp] = 1
        kprev[grp] = 0
    # the flags so far spread to the later groups with rows, as every later round's do
    for grp in range(2 * N):
        if kpos[grp] != 0:
            kpos[grp] = 2
    _flag_later_groups(kpos, m_soft, m, rgrp, N, gsum)
    full = False
    for _round in range(2 * N + 1):
        nk = 0
        if full or (code != 0 and _round == 0):
            # no (useful) flags: a slack on every group that has rows
            nflag = 0
            for grp in range(2 * N):
                nflag += 1 if kpos[grp] != 0 else 0
            if full or nflag == 0:
                for grp in range(2 * N):
                    kpos[grp] = 0
                for rr in range(m_soft, m):
                    kpos[rgrp[rr]] = 1
                full = True
        for grp in range(2 * N):
            if kpos[grp] != 0:
                kpos[grp] = nk + 1  # 1-based slack position
                nk += 1
        n2 = nzu + nk
        for a in range(nk):
            jj = nzu + a
            for cc in range(n2):
                H[jj, cc] = 0.0
                H[cc, jj] = 0.0
        for grp in range(2 * N):
            if kpos[grp] > 0:
                jj = nzu + kpos[grp] - 1
                H[jj, jj] = 2.0 * (w2l if grp < N else w2o)
                g[jj] = w1l if grp < N else w1o
        for rr in range(m_soft, m):
            for cc in range(nzu, n2):
                C[rr, cc] = 0.0
            grp = rgrp[rr]
            rowspan[rr, 1] = -1
            if kpos[grp] > 0:
                C[rr, nzu + kpos[grp] - 1] = 1.0
                rowspan[rr, 1] = nzu + kpos[grp] - 1
        for a in range(nk):
            rr = m + a
            for cc in range(n2):
                C[rr, cc] = 0.0
            C[rr, nzu + a] = 1.0
            b[rr] = 0.0
            rowcol[rr] = nzu + a
            isact[rr] = 0  # the slacks are renumbered: only the rows of C z >= b keep a guess
        # the rows active at the end of the solve before (as a guess: the same rows, slacks on
        # more groups) are added first
        code, it2 = gi_solve(
            H, g, C, b, m + nk, n2, z, lam, active, isact, rowcol, rowspan, L, J, Rq, d, zdir, r, uq, sq, rown,
            max_iter, tol,
        )  # fmt: skip
        iters += it2
        if code != 0:
            if full:
                return code, iters
            full = True
            continue
        for grp in range(2 * N):
            if kpos[grp] > 0:
                kpos[grp] = 1
        if _group_excess(lam, m_soft, m, rgrp, N, w1l, w1o, gsum, kpos, False):
            for grp in range(2 * N):
                kprev[grp] = kpos[grp]
            return 0, iters
        _flag_later_groups(kpos, m_soft, m, rgrp, N, gsum)
    return 3, iters


@subroutine
def condensed_solve(qp, work, x, u_prev, nx, nu, rows):
    """Solve one step's stage QP ``qp`` (:class:`~mpcdrive.ocp.stage_qp.StageQp`, its struct)
    from state ``x`` (nx,) after input ``u_prev`` (nu,), condensed onto the inputs (and the
    slacks of the soft rows), in the work arrays of ``work`` (:class:`CondensedWork`, its
    struct); returns ``(code, iterations)`` (code 0: ok, 1 infeasible, 2 max_iter, 3 failed)
    with the planned inputs in ``work.z[:N nu]``. The rows of ``C z >= b``: the first
    ``m_const`` constant (input bounds, their b from the stage's ``ulo``, ``uhi``; rates, the u_0
    rate rows from row ``r_rate0`` following ``u_prev``), then the state, road and obstacle rows
    of the step. ``riccati``: the unconstrained minimizer is tried first (no Rc, no soft rows);
    ``gamma``: there are state, road or obstacle rows. Nothing is allocated. ``nx``, ``nu``: the
    sizes ``qp.nx``, ``qp.nu`` (code 3 otherwise); a caller that hands them in as constants gets
    a copy of the solver specialized to them (the Riccati shortcut's small loops unrolled, the
    other sizes' copies left out). ``rows``: the step may have rows after the constant ones
    (``work.gamma``; code 3 if it has and ``rows`` is False); a constant False leaves their code
    (and that of the soft rows) out.
    """
    if nx != qp.nx or nu != qp.nu:
        return 3, 0
    if not rows and work.gamma:
        return 3, 0
    N, nz = qp.N, work.nz
    A, B, c, We, qt, Rm, Rc, uref = qp.A, qp.B, qp.c, qp.We, qp.qt, qp.R, qp.Rc, qp.uref
    ulo, uhi, dmax, x_min, x_max = qp.ulo, qp.uhi, qp.dmax, qp.x_min, qp.x_max
    lane, lane_n, lane_b, lane_lo, lane_hi = qp.lane, qp.lane_n, qp.lane_b, qp.lane_lo, qp.lane_hi
    lane_dlo, lane_dhi, Xlin, nrow, rowa, rowb = qp.lane_dlo, qp.lane_dhi, qp.Xlin, qp.nrow, qp.rowa, qp.rowb
    lane_t = qp.lane_t
    C, b, rowcol, rgrp, kpos = work.C, work.b, work.rowcol, work.rgrp, work.kpos
    rowspan = work.rowspan
    xf, P, lam, Vb, S, T2, Gam = work.xf, work.P, work.lam, work.Vb, work.S, work.T2, work.Gam
    H, g, z, L, J, Rq = work.H, work.g, work.z, work.L, work.J, work.Rq
    d, zdir, r, uq = work.d, work.zdir, work.r, work.uq
    sq, rown, lamq, active, isact, gsum = work.sq, work.rown, work.lamq, work.active, work.isact, work.gsum
    Kg, kf, PA, Mg, Gg, qv = work.Kg, work.kf, work.PA, work.Mg, work.Gg, work.qv
    tol = work.tol
    input_bound_rows(N, nu, qp.u_min, qp.u_max, ulo, uhi, C, b, False)
    nzu = N * nu
    # -- no Rc, no lane: try the unconstrained minimizer (Riccati, O(N)); if it satisfies every
    # bound it is the QP's solution ---------------------------------------------------------------
    if work.riccati:
        if riccati(N, nx, nu, A, B, c, qt, uref, We, Rm, x, P, lam, Kg, kf, PA, Mg, Gg, qv, z):
            if plan_feasible(N, nx, nu, z, lam, u_prev, ulo, uhi, dmax, x_min, x_max, tol):
                return 0, 0

    # -- condensing: x_k = xf_k + sum_j G_kj u_j ----------------------------------------------
    for i in range(nx):
        xf[0, i] = x[i]
    for k in range(N):
        for i in range(nx):
            t = c[k, i]
            for j in range(nx):
                t += A[k, i, j] * xf[k, j]
            xf[k + 1, i] = t
    # P_N = W_N ; P_k = W_k + A_k' P_{k+1} A_k ; lam_k = W_k e_k + A_k' lam_{k+1}
    for i in range(nx):
        for j in range(nx):
            P[N, i, j] = We[N - 1, i, j]
    for i in range(nx):
        t = -qt[N - 1, i]
        for j in range(nx):
            t += We[N - 1, i, j] * xf[N, j]
        lam[N, i] = t
    for k in range(N - 1, 0, -1):
        for i in range(nx):
            for j in range(nx):
                t = 0.0
                for l in range(nx):
                    t += P[k + 1, i, l] * A[k, l, j]
                T2[i, j] = t  # P_{k+1} A_k (T2 is nx x max(nx, nu))
        for i in range(nx):
            for j in range(nx):
                t = We[k - 1, i, j]
                for l in range(nx):
                    t += A[k, l, i] * T2[l, j]
                P[k, i, j] = t
        for i in range(nx):
            t = -qt[k - 1, i]
            for j in range(nx):
                t += We[k - 1, i, j] * xf[k, j] + A[k, j, i] * lam[k + 1, j]
            lam[k, i] = t
    # gradient
    for k in range(N):
        for a in range(nu):
            t = 0.0
            for i in range(nx):
                t += B[k, i, a] * lam[k + 1, i]
            for e in range(nu):
                t -= Rm[a, e] * uref[k, e]
            g[k * nu + a] = 2.0 * t
    for a in range(nu):
        t = 0.0
        for e in range(nu):
            t += Rc[a, e] * u_prev[e]
        g[a] -= 2.0 * t
    # Hessian blocks: H_jj = 2 (B_j' V_j + R + Rc terms) with V_j = P_{j+1} B_j, and for i < j
    # H_ij = 2 B_i' T_ij, T_ij = A_{i+1}' T_{i+1,j}, T_{j-1,j} = A_j' V_j: all T_i. side by side
    # in S (nx, N nu) so the products run along long rows
    for j in range(N):
        for i in range(nx):
            for a in range(nu):
                t = 0.0
                for l in range(nx):
                    t += P[j + 1, i, l] * B[j, l, a]
                Vb[j, i, a] = t
        rcw = 2.0 if j < N - 1 else 1.0
        for a in range(nu):
            for e in range(nu):
                t = 0.0
                for l in range(nx):
                    t += B[j, l, a] * Vb[j, l, e]
                H[j * nu + a, j * nu + e] = 2.0 * (t + Rm[a, e] + rcw * Rc[a, e])
    cur = 0
    for i in range(N - 2, -1, -1):
        c0 = (i + 1) * nu
        nxt = 1 - cur
        for l in range(nx):
            for a in range(nu):
                S[cur, l, c0 + a] = Vb[i + 1, l, a]
        for l in range(nx):
            for cc in range(c0, nzu):
                S[nxt, l, cc] = 0.0
            for m_ in range(nx):
                am = A[i + 1, m_, l]
                if am != 0.0:
                    for cc in range(c0, nzu):
                        S[nxt, l, cc] += am * S[cur, m_, cc]
        for a in range(nu):
            row = i * nu + a
            for cc in range(c0, nzu):
                H[row, cc] = 0.0
            for e in range(nu):
                H[row, c0 + e] = -2.0 * Rc[a, e]
            for l in range(nx):
                bl = 2.0 * B[i, l, a]
                if bl != 0.0:
                    for cc in range(c0, nzu):
                        H[row, cc] += bl * S[nxt, l, cc]
            for cc in range(c0, nzu):
                H[cc, row] = H[row, cc]
        cur = nxt

    # -- constraint rows that change each step -------------------------------------------------
    r0 = work.r_rate0
    for a in range(nu):
        if math.isfinite(dmax[a]):
            b[r0] = u_prev[a] - dmax[a]
            b[r0 + 1] = -u_prev[a] - dmax[a]
            r0 += 2
    m = work.m_const
    m_lane = m
    if rows and work.gamma:
        # Gam[k] = d x_{k+1} / d z: Gam[k] = A_k Gam[k-1] in the first k blocks, B_k in block k,
        # zero after it (never written)
        for k in range(N):
            for i in range(nx):
                for cc in range(k * nu):
                    Gam[k, i, cc] = 0.0
                for l in range(nx):
                    al = A[k, i, l]
                    if al != 0.0:
                        for cc in range(k * nu):
                            Gam[k, i, cc] += al * Gam[k - 1, l, cc]
                for a in range(nu):
                    Gam[k, i, k * nu + a] = B[k, i, a]
        for k in range(1, N + 1):
            for i in range(nx):
                if math.isfinite(x_min[i]):
                    rowcol[m] = -1
                    rowspan[m, 0] = k * nu  # x_k depends on u_0 .. u_{k-1} only
                    rowspan[m, 1] = -1
                    for jj in range(nzu):
                        C[m, jj] = Gam[k - 1, i, jj]
                    for jj in range(nzu, nz):
                        C[m, jj] = 0.0
                    b[m] = x_min[i] - xf[k, i]
                    m += 1
                if math.isfinite(x_max[i]):
                    rowcol[m] = -1
                    rowspan[m, 0] = k * nu
                    rowspan[m, 1] = -1
                    for jj in range(nzu):
                        C[m, jj] = -Gam[k - 1, i, jj]
                    for jj in range(nzu, nz):
                        C[m, jj] = 0.0
                    b[m] = xf[k, i] - x_max[i]
                    m += 1
        if lane:
            m_lane = m
            Xl = Xlin
            for k in range(1, N + 1):
                # n . p - dhi w <= lane_b + hi - dhi wbar (and the same with lo, >=): the road's
                # bounds linearized in the body's yaw relative to the road, w = yaw - t . p with
                # t the road's turn per metre moved (scene.road.body_bounds; ocp.stage_qp)
                n0, n1 = lane_n[k - 1, 0], lane_n[k - 1, 1]
                t0, t1 = lane_t[k - 1, 0], lane_t[k - 1, 1]
                dh, dl = lane_dhi[k - 1], lane_dlo[k - 1]
                nxf = n0 * xf[k, 0] + n1 * xf[k, 1]
                ybar = Xl[k, 2] - t0 * Xl[k, 0] - t1 * Xl[k, 1]
                wf = xf[k, 2] - t0 * xf[k, 0] - t1 * xf[k, 1]
                for jj in range(nzu):
                    gp = n0 * Gam[k - 1, 0, jj] + n1 * Gam[k - 1, 1, jj]
                    gy = Gam[k - 1, 2, jj] - t0 * Gam[k - 1, 0, jj] - t1 * Gam[k - 1, 1, jj]
                    C[m, jj] = -(gp - dh * gy)
                    C[m + 1, jj] = gp - dl * gy
                for jj in range(nzu, nz):
                    C[m, jj] = 0.0
                    C[m + 1, jj] = 0.0
                b[m] = nxf - dh * wf - lane_b[k - 1] - lane_hi[k - 1] + dh * ybar
                b[m + 1] = lane_b[k - 1] + lane_lo[k - 1] - dl * ybar - (nxf - dl * wf)
                rgrp[m] = k - 1
                rgrp[m + 1] = k - 1
                rowcol[m] = -1
                rowcol[m + 1] = -1
                rowspan[m, 0] = k * nu
                rowspan[m + 1, 0] = k * nu
                rowspan[m, 1] = -1
                rowspan[m + 1, 1] = -1
                m += 2
        if nrow > 0:
            # obstacle half-planes a . (x_k, y_k, yaw_k) >= b of this step (b = -inf: unused)
            if not lane:
                m_lane = m
            for k in range(1, N + 1):
                for q in range(nrow):
                    if not rowb[k - 1, q] > -math.inf:
                        continue
                    r0_, r1_, r2_ = rowa[k - 1, q, 0], rowa[k - 1, q, 1], rowa[k - 1, q, 2]
                    for jj in range(nzu):
                        C[m, jj] = r0_ * Gam[k - 1, 0, jj] + r1_ * Gam[k - 1, 1, jj] + r2_ * Gam[k - 1, 2, jj]
                    for jj in range(nzu, nz):
                        C[m, jj] = 0.0
                    b[m] = rowb[k - 1, q] - (r0_ * xf[k, 0] + r1_ * xf[k, 1] + r2_ * xf[k, 2])
                    rgrp[m] = N + k - 1
                    rowcol[m] = -1
                    rowspan[m, 0] = k * nu
                    rowspan[m, 1] = -1
                    m += 1

    # -- solve, then the plan and the command --------------------------------------------------
    if not rows or (not lane and nrow == 0):
        m_lane = m  # no soft rows (soft_solve then solves the hard QP once)
    else:
        # soft rows (slack groups: lane rows of step k in group k, obstacle rows in N + k) that
        # the linearization trajectory is on or beyond (within 1 mm)
        for k in range(2 * N):
            kpos[k] = 0
        if lane:
            for k in range(N):
                px, py = Xlin[k + 1, 0], Xlin[k + 1, 1]
                dev = lane_n[k, 0] * px + lane_n[k, 1] * py - lane_b[k]
                if dev > lane_hi[k] - 1e-3 or dev < lane_lo[k] + 1e-3:
                    kpos[k] = 1
        if nrow > 0:
            for k in range(N):
                Xl = Xlin[k + 1]
                for q in range(nrow):
                    if rowb[k, q] > -math.inf and (
                        rowa[k, q, 0] * Xl[0] + rowa[k, q, 1] * Xl[1] + rowa[k, q, 2] * Xl[2] < rowb[k, q] + 1e-3
                    ):
                        kpos[N + k] = 1
        for f0 in range(0, 2 * N, N):  # and the 3 steps after each (RTI plans move a little)
            for k in range(N - 1, 0, -1):
                if kpos[f0 + k - 1] == 1 or (k >= 2 and kpos[f0 + k - 2] == 1) or (k >= 3 and kpos[f0 + k - 3] == 1):
                    kpos[f0 + k] = 1
    code, iters = soft_solve(
        H, g, C, b, m, m_lane, rgrp, N, nzu, kpos, qp.w2_lane, qp.w1_lane, qp.w2_obs, qp.w1_obs, gsum, z, lamq, active, isact,
        rowcol, rowspan, L, J, Rq, d, zdir, r, uq, sq, rown, work.max_iter, tol, rows, work.kprev,
    )  # fmt: skip
    return code, iters


@subroutine
def shift_soft_guess(work, N, new_plan):
    """Move the slack groups of the last solve with slacks (``work.kprev``) on by a step for the
    next control step's (its plan is the last one's shifted), or drop them (``new_plan`` False: no
    plan to go on from, e.g. the first step)."""
    kprev = work.kprev
    for f0 in range(0, 2 * N, N):
        for k in range(N):
            if not new_plan:
                kprev[f0 + k] = 0
            elif k < N - 1:
                kprev[f0 + k] = kprev[f0 + k + 1]


@subroutine
def input_bound_rows(N, nu, u_min, u_max, lo, hi, C, b, write_rows):
    """The input-bound rows of ``C z >= b``, which lead the constant rows: stage by stage, input
    by input, ``u_ka >= lo[k, a]`` then ``-u_ka >= -hi[k, a]``, each only where the problem's bound
    (``u_min``, ``u_max``) is finite. Writes their ``b`` (and, with ``write_rows``, their unit
    entries of C); returns how many there are."""
    r = 0
    for k in range(N):
        for a in range(nu):
            for upper in (False, True):
                if not math.isfinite(u_max[a] if upper else u_min[a]):
                    continue
                if write_rows:
                    C[r, k * nu + a] = -1.0 if upper else 1.0
                b[r] = -hi[k, a] if upper else lo[k, a]
                r += 1
    return r


@subroutine
def write_plan(qp, z, x, out):
    """The plan of the solution ``z`` of ``qp`` (its struct) from state ``x``: ``out = [u (nu) =
    U_0 clipped to the first stage's input bounds, X ((N+1) nx) rolled out through the affine
    model, U (N nu), xref ((N+1) nx)]``."""
    N, nx, nu = qp.N, qp.nx, qp.nu
    A, B, c, xref, ulo, uhi = qp.A, qp.B, qp.c, qp.xref, qp.ulo, qp.uhi
    oX = nu
    oU = oX + (N + 1) * nx
    oR = oU + N * nu
    for i in range(nx):
        out[oX + i] = x[i]
    for k in range(N):
        for i in range(nx):
            t = c[k, i]
            for j in range(nx):
                t += A[k, i, j] * out[oX + k * nx + j]
            for a in range(nu):
                t += B[k, i, a] * z[k * nu + a]
            out[oX + (k + 1) * nx + i] = t
    for j in range(N * nu):
        out[oU + j] = z[j]
    for k in range(N + 1):
        for i in range(nx):
            out[oR + k * nx + i] = xref[k, i]
    for a in range(nu):
        out[a] = min(max(z[a], ulo[0, a]), uhi[0, a])


@dataclass(frozen=True, eq=False)
class CondensedWork:
    """What :func:`condensed_solve` works in, sized once for a problem (see
    :func:`mpcdrive.solvers.condensed_setup.new_condensed_work`): ``nz`` variables (inputs and
    slacks), ``mq`` rows of ``C z >= b`` at most, the first ``m_const`` constant (the u_0 rate
    rows from ``r_rate0``), ``rowcol`` the single nonzero column of each constant row (-1:
    dense), ``rowspan`` (mq, 2) where each row may be nonzero (its leading columns, one more
    column: :func:`~mpcdrive.solvers.dense_qp.gi_solve`); ``gamma``: the step adds state, road
    or obstacle rows; ``riccati``: try the unconstrained minimizer first; ``max_iter``
    active-set changes at most, ``tol`` the feasibility tolerance of a row (scaled by its norm).
    The rest is work space: the condensing (``xf``, ``P``, ``lam``, ``Vb``, ``S``, ``T2``,
    ``Gam``), the QP (``H``, ``g``, the solution ``z``) and the active-set method (``L``, ``J``,
    ``Rq``, ``d``, ``zdir``, ``r``, ``uq``, ``sq``, ``rown``, ``lamq``, ``active``, ``isact``,
    ``rgrp``, ``kpos``, ``gsum``; ``kprev`` the slack groups of the last solve, kept for the
    next), the Riccati recursion (``Kg``, ``kf``, ``PA``, ``Mg``, ``Gg``, ``qv``)."""

    nz: int
    mq: int
    m_const: int
    r_rate0: int
    gamma: bool
    riccati: bool
    max_iter: int
    tol: float
    C: np.ndarray
    b: np.ndarray
    rowcol: np.ndarray
    rowspan: np.ndarray
    xf: np.ndarray
    P: np.ndarray
    lam: np.ndarray
    Vb: np.ndarray
    S: np.ndarray
    T2: np.ndarray
    Gam: np.ndarray
    H: np.ndarray
    g: np.ndarray
    z: np.ndarray
    L: np.ndarray
    J: np.ndarray
    Rq: np.ndarray
    d: np.ndarray
    zdir: np.ndarray
    r: np.ndarray
    uq: np.ndarray
    sq: np.ndarray
    rown: np.ndarray
    lamq: np.ndarray
    active: np.ndarray
    isact: np.ndarray
    rgrp: np.ndarray
    kpos: np.ndarray
    kprev: np.ndarray
    gsum: np.ndarray
    Kg: np.ndarray
    kf: np.ndarray
    PA: np.ndarray
    Mg: np.ndarray
    Gg: np.ndarray
    qv: np.ndarray

    def struct(self):
        """The compiled struct of this work space (the same arrays)."""
        return to_struct(self, _build_condensed_work)


_CondensedWorkType, _CondensedWorkStruct = define_struct(CondensedWork, __name__)


@njit(cache=True)
def _build_condensed_work(values):
    return _CondensedWorkStruct(*values)


# numba keys this module's cache to this file only; soft_solve and condensed_solve link in code from dense_qp
from .. import _jitcache  # noqa: E402
from . import dense_qp as _dense_qp  # noqa: E402

_jitcache.refresh(soft_solve, [f for f in (_dense_qp.__file__,) if f is not None])
