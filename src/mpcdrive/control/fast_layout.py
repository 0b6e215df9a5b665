"""The layout of the buffers of the compiled step (:mod:`mpcdrive.control.fast_step`).

:class:`~mpcdrive.control.fast.CompiledLtvMpc` keeps every float array of a controller in one buffer
(``wbuf``), and the integer parameters, the layout of ``wbuf`` and the active-set work in another
(``ibuf``), both allocated at construction. The constants here name their parts: ``_I_*`` the
integer parameters, ``_F_*`` the float parameters, ``_W_*`` the arrays of ``wbuf``, ``_OB_*``
the columns of the obstacle table, ``_O_*`` the info outputs; and the codes the step is given
(``_SIDE_*``, ``_OBS_*``, ``MODE_*``, ``STAGE_*``).

The compiled code reads them as compile-time constants, so this file is one of the sources the
step's numba cache follows (see :mod:`mpcdrive._jitcache`).
"""

from __future__ import annotations

# integer parameters (ip)
(
    _I_MODEL,
    _I_NX,
    _I_NU,
    _I_N,
    _I_PATH,
    _I_LIN,
    _I_METHOD,
    _I_HORIZON,
    _I_FF,
    _I_LANE,
    _I_MCONST,
    _I_RATE0,
    _I_MAXITER,
    _I_GAMMA,
    _I_NZ,
    _I_RICCATI,
    _I_MQ,
    _I_OFORM,
    _I_NOBS,
    _I_OMAX,
    _I_DETOUR,
    _I_OROWS,
    _I_PROFILE,
    _I_ACCEL,
    _I_STEER,
    _I_FRICTION,
    _I_NSEL,
) = range(27)
_NIP = 27
# passing sides (as ocp.avoidance), and "not chosen yet" in the compiled side memory
_SIDE_LEFT, _SIDE_RIGHT, _SIDE_BLOCKED, _SIDE_NONE = 1, -1, 0, 2
# obstacle cost formulations (ip[_I_OFORM])
_OBS_NONE, _OBS_POTENTIAL, _OBS_GAUSSIAN = 0, 1, 2
# linearization modes of a step: no plan (roll out the references), the previous step's plan
# shifted by one step (real-time iteration), the current SQP iterate as it is
MODE_NO_PLAN, MODE_SHIFTED_PLAN, MODE_ITERATE = 0, 1, 2
# stages of a step: all of it; up to the linearization trajectory (obstacle rows are built from it
# in Python by ``ocp.avoidance``); the rest, with those rows in the buffers; of the rest, only
# the stage costs and road rows (the stage QP complete in the buffers, for another solver)
STAGE_ALL, STAGE_LINEARIZE, STAGE_SOLVE, STAGE_COST = 0, 1, 2, 3
# columns of an obstacle row: pose (x, y) [m] at t = 0, velocity (vx, vy) [m/s], bounding radius
# [m], offset (x, y) [m] of the point projected for the path heading, projection window extra [m]
_OB_X, _OB_Y, _OB_VX, _OB_VY, _OB_RB, _OB_OX, _OB_OY, _OB_WIN = range(8)
_NOB = 8
# the float arrays of a controller, all views of one buffer (one argument to the compiled step:
# passing arrays one by one costs about 0.1 us each in the call)
(
    _W_FP,
    _W_MP,
    _W_BND,
    _W_GEO,
    _W_WQ,
    _W_RM,
    _W_RC,
    _W_TABS,
    _W_TABXY,
    _W_TABH,
    _W_TABK,
    _W_C,
    _W_B,
    _W_REFS,
    _W_XREF,
    _W_UREF,
    _W_XBAR,
    _W_UBAR,
    _W_F,
    _W_A,
    _W_BD,
    _W_CD,
    _W_LANEN,
    _W_LANEB,
    _W_XF,
    _W_P,
    _W_LAM,
    _W_VB,
    _W_S,
    _W_T2,
    _W_GAM,
    _W_H,
    _W_G,
    _W_Z,
    _W_L,
    _W_J,
    _W_RQ,
    _W_D,
    _W_ZDIR,
    _W_R,
    _W_UQ,
    _W_SQ,
    _W_ROWN,
    _W_LAMQ,
    _W_DW,
    _W_KG,
    _W_KF,
    _W_PA,
    _W_MG,
    _W_GG,
    _W_QV,
    _W_WE,
    _W_QT,
    _W_OBS,
    _W_ODIST,
    _W_OPROJ,
    _W_SARR,
    _W_EREF,
    _W_ROWA,
    _W_ROWB,
    _W_LLO,
    _W_LHI,
    _W_XLIN,
    _W_GSUM,
    _W_PROF,
    _W_VARR,
    _W_REFW,
    _W_RDS,
    _W_RDL,
    _W_RDR,
    _W_LDLO,
    _W_LDHI,
    _W_ULO,
    _W_UHI,
    _W_VLIN,
    _W_SLIN,
    _W_RLIN,
) = range(77)
_NW = 77
# float parameters (fp)
(
    _F_DT,
    _F_VREF,
    _F_HSTEP,
    _F_WINDOW,
    _F_RMARGIN,
    _F_SLACK2,
    _F_SLACK1,
    _F_TOL,
    _F_OW,
    _F_OEPS,
    _F_OSX,
    _F_OSY,
    _F_OINF,
    _F_OMARGIN,
    _F_HW,
    _F_HL,
    _F_RAMP,
    _F_OSLACK2,
    _F_OSLACK1,
    _F_BOFF,
    _F_RPERIOD,
    _F_FRIC,
    _F_WHEELBASE,
) = range(23)
_NFP = 23
# info outputs
_O_S, _O_EY, _O_EPSI, _O_ITER = range(4)
