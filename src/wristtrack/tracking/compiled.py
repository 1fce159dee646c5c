"""The tracker's fast step as one compiled function (numba; optional: ``wristtrack[fast]``).

``tracker._FastStep`` in NumPy is already a few dozen whole-array calls, and with a frame's
arrays this small (37 sigma points, 12-D tangent, 6 markers x 3 measurements) those calls'
overhead is nearly all of its cost. This is the same computation written as plain loops and
compiled, so a frame is one call: the augmented sigma points, their propagation and lifts
(``motion.SigmaPropagator``), the marker measurements (``MarkerObservation.measure_columns``),
the joint moments (``ukf.SigmaColumns``), the visibility test, the block-Cholesky gate and
nearest-blob assignment (``associate.BlockGate``) and the joint Cholesky correction
(``ukf.joint_correct``). Equal to the NumPy path to rounding (tests/test_fast_path.py).

Only the common frame is handled here. The compiled step returns DECLINED, having changed
nothing, where the NumPy path has a branch this does not copy: a covariance that is not
positive definite (its Cholesky fallbacks), a marker out of view (the generic path), a NaN
distance or two markers wanting one blob (the assignment solver). The caller then runs the NumPy
path, the reference, on the same frame.

Without numba, ``AVAILABLE`` is False and the tracker uses the NumPy path only. The compiled
code is cached on disk (numba ``cache=True``, in ``__pycache__`` beside this file), so only the
first process after a change pays the compile (about 10-15 s of CPU); later ones load it (~1 s).
"""

from __future__ import annotations

import math
from importlib.util import find_spec
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from wristtrack.camera import Camera
    from wristtrack.tracking.models import ProcessNoise
    from wristtrack.tracking.observation import MeasurementNoise

# numba is optional and imported only when a tracker first takes the fast path (importing it
# costs about a second); without it the NumPy path, the reference, does the work
AVAILABLE = find_spec("numba") is not None

OK = 0  # the frame is done: the outputs are valid
DECLINED = 1  # the NumPy path must take this frame (see the module's docstring)

# Layout of the ``par`` vector of constants (built by ``constants``).
(
    _SCALE, _FX, _FY, _CX, _CY, _U_MAX, _V_MAX, _PIXEL_VAR, _DEPTH_COEFF, _DEPTH_FLOOR,
    _SQRT_QA, _SQRT_QW, _FACING_COS, _GATE_CONSTANT, _HALF_GATE, _N_PAR,
) = range(16)  # fmt: skip


def constants(
    scale: float,
    camera: Camera,
    noise: MeasurementNoise,
    process: ProcessNoise,
    facing_cos: float,
    gate_constant: float,
    half_gate: float,
) -> np.ndarray:
    """The scalar constants of the step as one array (one argument for the compiled call)."""
    par = np.empty(_N_PAR)
    par[_SCALE] = scale
    par[_FX], par[_FY], par[_CX], par[_CY] = camera.fx, camera.fy, camera.cx, camera.cy
    par[_U_MAX], par[_V_MAX] = camera.width - 0.5, camera.height - 0.5
    par[_PIXEL_VAR] = noise.pixel_sigma**2
    par[_DEPTH_COEFF], par[_DEPTH_FLOOR] = noise.depth_coeff, noise.depth_floor
    par[_SQRT_QA] = math.sqrt(process.linear_accel)
    par[_SQRT_QW] = math.sqrt(process.angular_accel)
    par[_FACING_COS] = facing_cos
    par[_GATE_CONSTANT], par[_HALF_GATE] = gate_constant, half_gate
    return par


# ------------------------------------------------------------------------ small helpers
# The same formulas as motion.quat_* (Hamilton convention, (w, x, y, z)), on arrays of 4.


def _quat_exp(x, y, z, out):
    h = 0.5 * math.sqrt(x * x + y * y + z * z + 1e-300)
    s = 0.5 * math.sin(h) / h
    out[0] = math.cos(h)
    out[1] = s * x
    out[2] = s * y
    out[3] = s * z


def _quat_mul(a, b, out):
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3]
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2]
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1]
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]


def _quat_of_matrix(x, q):
    """motion.quat_of_matrix (Shepperd's method) of the row-major rotation in x[:9]."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
        x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8]
    )  # fmt: skip
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(1.0 + tr)
        q[0], q[1], q[2], q[3] = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r00 - tr)
        q[0], q[1], q[2], q[3] = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r11 - tr)
        q[0], q[1], q[2], q[3] = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r22 - tr)
        q[0], q[1], q[2], q[3] = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s


def _quat_to_matrix(q, R):
    """motion.quat_to_matrix into R (3, 3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = w * w + x * x - y * y - z * z
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = w * w - x * x + y * y - z * z
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = w * w - x * x - y * y + z * z


def _cholesky(A, L):
    """Lower Cholesky factor of A (n, n) (from its lower triangle) into L (n, n), zeros above
    the diagonal; False where A is not positive definite (or has a NaN), as LAPACK's dpotrf
    reports it."""
    n = A.shape[0]
    for j in range(n):
        for i in range(j):
            L[i, j] = 0.0
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    return True


def _forward(L, B):
    """B <- L^-1 B in place, L (n, n) lower triangular, B (n, c)."""
    n, c = B.shape
    for i in range(n):
        d = L[i, i]
        for col in range(c):
            t = B[i, col]
            for k in range(i):
                t -= L[i, k] * B[k, col]
            B[i, col] = t / d


# --------------------------------------------------------------------------- the step


def _step(x, P, dt, uv, depth, layout, R_c0, t_c0, wm, wc, par):
    """One tracking frame: (code, x, P, labels, markers associated, NIS); see the module.

    x (18,) state [R row-major, p, v, w] and P (12, 12) its tangent covariance; dt the step;
    uv (M, 2) and depth (M,) the blobs (all depths finite); layout (J, 3) the markers in the hand
    frame; R_c0, t_c0 the camera pose of W0; wm, wc (S,) the unscented weights, S = 37 sigma
    points ordered as ukf.SigmaColumns; par the constants (``constants``).
    """
    n, M, m = 12, uv.shape[0], 3 * layout.shape[0]
    labels = np.empty(M, dtype=np.int64)
    for i in range(M):
        labels[i] = -1
    x_out = np.empty(18)
    P_out = np.empty((n, n))
    L = np.empty((n, n))
    if not _cholesky(P, L):
        return DECLINED, x_out, P_out, labels, 0, np.nan

    # predict: W holds one row per sigma point, columns [0, m) its measurements, axis-major
    # (u of each marker, then v, then z), columns [m, m + 12) its lift about the propagated centre
    qs = np.empty(4)  # the state's orientation
    qc = np.empty(4)  # the centre's turn over dt
    W = np.empty((wm.shape[0], m + n))
    _sigma_points(x, L, dt, layout, R_c0, t_c0, par, qs, qc, W)
    mean = np.empty(m + n)
    C = np.empty((m + n, m + n))
    _moments(W, wm, wc, mean, C)
    q = np.empty(4)  # the predicted orientation, pvw its p, v, w
    pvw = np.empty(9)
    _predicted(x, dt, mean[m:], qs, qc, q, pvw)
    if not _all_visible(q, pvw, layout, R_c0, t_c0, par):
        return DECLINED, x_out, P_out, labels, 0, np.nan

    # associate
    _add_noise(C, mean, layout.shape[0], par)  # C's measurement block becomes Pyy + R
    blob_of = np.empty(layout.shape[0], dtype=np.int64)
    n_pairs = _associate(C, mean, uv, depth, par, labels, blob_of)
    if n_pairs < 0:
        return DECLINED, x_out, P_out, labels, 0, np.nan

    # update
    nis = np.nan
    if n_pairs == 0:  # coasting: the prediction
        for i in range(n):
            for j in range(n):
                P_out[i, j] = 0.5 * (C[m + i, m + j] + C[m + j, m + i])
    else:
        nis = _correct(C, mean, uv, depth, blob_of, n_pairs, q, pvw, P_out)
        if nis != nis:
            return DECLINED, x_out, P_out, labels, 0, np.nan
    _write_state(q, pvw, x_out)
    return OK, x_out, P_out, labels, n_pairs, nis


def _sigma_points(x, L, dt, layout, R_c0, t_c0, par, qs, qc, W):
    """The augmented sigma points retracted, propagated, measured and lifted (the rows of W),
    as SigmaPropagator and MarkerObservation.measure_columns; qs, qc get the state's orientation
    and the centre's turn."""
    J, n, S = layout.shape[0], 12, W.shape[0]
    m = 3 * J
    scale = par[_SCALE]
    sqdt = math.sqrt(dt)
    sa_v = par[_SQRT_QA] * sqdt  # velocity change per unit noise offset: sqrt(q_a / dt) dt
    sa_p = 0.5 * sa_v * dt  # position change: sqrt(q_a / dt) dt^2 / 2
    sw_w = par[_SQRT_QW] * sqdt
    sw_turn = 0.5 * sw_w * dt  # the midpoint rate's share of the turn
    fx, fy, cx, cy = par[_FX], par[_FY], par[_CX], par[_CY]
    _quat_of_matrix(x, qs)
    _quat_exp(x[15] * dt, x[16] * dt, x[17] * dt, qc)  # the centre turns by w dt
    qc[1:] = -qc[1:]  # conj(q_centre): sigma rotations relative to the centre's
    off = np.empty(n + 6)  # the sigma point's tangent offset and noise offset
    r = np.empty(4)
    t = np.empty(4)
    tr = np.empty(4)
    o = np.empty(4)
    R = np.empty((3, 3))
    for s in range(S):
        # the order of ukf.SigmaColumns: 0, +scale L[:, k], -scale L[:, k], +noise, -noise
        for i in range(n + 6):
            off[i] = 0.0
        if 1 <= s <= n:
            for i in range(n):
                off[i] = scale * L[i, s - 1]
        elif n < s <= 2 * n:
            for i in range(n):
                off[i] = -scale * L[i, s - 1 - n]
        elif 2 * n < s <= 2 * n + 6:
            off[s - 1 - n] = scale
        elif s > 2 * n + 6:
            off[s - 7 - n] = -scale
        # lifts of p, v, w: the propagated point minus the propagated centre (the state cancels)
        for i in range(3):
            W[s, m + 3 + i] = off[3 + i] + dt * off[6 + i] + sa_p * off[12 + i]
            W[s, m + 6 + i] = off[6 + i] + sa_v * off[12 + i]
            W[s, m + 9 + i] = off[9 + i] + sw_w * off[15 + i]
        # orientation t r q_state: retraction r = exp(dphi), turn t = exp(dt (w + dw) + the
        # midpoint share of the angular acceleration)
        _quat_exp(off[0], off[1], off[2], r)
        _quat_exp(
            dt * (x[15] + off[9]) + sw_turn * off[15],
            dt * (x[16] + off[10]) + sw_turn * off[16],
            dt * (x[17] + off[11]) + sw_turn * off[17],
            t,
        )
        _quat_mul(t, r, tr)
        _quat_mul(tr, qs, o)
        # log of the rotation relative to the centre's, t r conj(q_centre) (right for either
        # sign of its w, as SigmaPropagator._lift_rotations)
        _quat_mul(tr, qc, r)
        nv = math.sqrt(1e-300 * r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3])
        k = 2.0 * math.atan(nv / r[0]) / nv
        for i in range(3):
            W[s, m + i] = r[1 + i] * k
        # the markers seen from the camera: R_c0 (R(o) T_j + p') + t_c0, projected
        _quat_to_matrix(o, R)
        px = x[9] + dt * x[12] + W[s, m + 3]
        py = x[10] + dt * x[13] + W[s, m + 4]
        pz = x[11] + dt * x[14] + W[s, m + 5]
        for j in range(J):
            a, b, c = layout[j, 0], layout[j, 1], layout[j, 2]
            hx = R[0, 0] * a + R[0, 1] * b + R[0, 2] * c + px
            hy = R[1, 0] * a + R[1, 1] * b + R[1, 2] * c + py
            hz = R[2, 0] * a + R[2, 1] * b + R[2, 2] * c + pz
            X = R_c0[0, 0] * hx + R_c0[0, 1] * hy + R_c0[0, 2] * hz + t_c0[0]
            Y = R_c0[1, 0] * hx + R_c0[1, 1] * hy + R_c0[1, 2] * hz + t_c0[1]
            Z = R_c0[2, 0] * hx + R_c0[2, 1] * hy + R_c0[2, 2] * hz + t_c0[2]
            W[s, j] = (fx * X + cx * Z) / Z
            W[s, J + j] = (fy * Y + cy * Z) / Z
            W[s, 2 * J + j] = Z
    qc[1:] = -qc[1:]


def _moments(W, wm, wc, mean, C):
    """Weighted means of W's columns (one row per sigma point) and their covariance; W is
    centred in place. The covariance is accumulated point by point, so the innermost loop runs
    along contiguous rows with no reduction in it (a dependency chain of one long sum per entry
    would cost several times more)."""
    S, rows = W.shape
    for r in range(rows):
        mean[r] = 0.0
    for s in range(S):
        for r in range(rows):
            mean[r] += W[s, r] * wm[s]
    for r in range(rows):
        for c in range(rows):
            C[r, c] = 0.0
    for s in range(S):
        for r in range(rows):
            W[s, r] -= mean[r]
        for r in range(rows):
            a = W[s, r] * wc[s]
            for c in range(r + 1):
                C[r, c] += a * W[s, c]
    for r in range(rows):
        for c in range(r):
            C[c, r] = C[r, c]


def _predicted(x, dt, lift, qs, qc, q, pvw):
    """The predicted state: the mean lift retracted about the propagated centre."""
    g = np.empty(4)
    e = np.empty(4)
    _quat_mul(qc, qs, g)
    _quat_exp(lift[0], lift[1], lift[2], e)
    _quat_mul(e, g, q)
    for i in range(3):
        pvw[i] = x[9 + i] + dt * x[12 + i] + lift[3 + i]
        pvw[3 + i] = x[12 + i] + lift[6 + i]
        pvw[6 + i] = x[15 + i] + lift[9 + i]


def _all_visible(q, pvw, layout, R_c0, t_c0, par):
    """MarkerObservation.all_visible: every marker in front, facing the camera, on the sensor."""
    R = np.empty((3, 3))
    _quat_to_matrix(q, R)
    Rc = np.empty((3, 3))
    tc = np.empty(3)
    for i in range(3):
        for j in range(3):
            Rc[i, j] = R_c0[i, 0] * R[0, j] + R_c0[i, 1] * R[1, j] + R_c0[i, 2] * R[2, j]
        tc[i] = R_c0[i, 0] * pvw[0] + R_c0[i, 1] * pvw[1] + R_c0[i, 2] * pvw[2] + t_c0[i]
    for j in range(layout.shape[0]):
        a, b, c = layout[j, 0], layout[j, 1], layout[j, 2]
        X = Rc[0, 0] * a + Rc[0, 1] * b + Rc[0, 2] * c + tc[0]
        Y = Rc[1, 0] * a + Rc[1, 1] * b + Rc[1, 2] * c + tc[1]
        Z = Rc[2, 0] * a + Rc[2, 1] * b + Rc[2, 2] * c + tc[2]
        if not Z > 0:
            return False
        facing = -(X * Rc[0, 2] + Y * Rc[1, 2] + Z * Rc[2, 2]) / math.sqrt(X * X + Y * Y + Z * Z)
        u = X / Z * par[_FX] + par[_CX]
        v = Y / Z * par[_FY] + par[_CY]
        if not (facing > par[_FACING_COS] and -0.5 <= u < par[_U_MAX] and -0.5 <= v < par[_V_MAX]):
            return False
    return True


def _add_noise(C, mean, J, par):
    """MarkerObservation.noise_variances added to the measurement block's diagonal."""
    for i in range(2 * J):
        C[i, i] += par[_PIXEL_VAR]
    for j in range(J):
        sd = par[_DEPTH_COEFF] * mean[2 * J + j] * mean[2 * J + j]
        if not sd > par[_DEPTH_FLOOR]:
            sd = par[_DEPTH_FLOOR]
        C[2 * J + j, 2 * J + j] += sd * sd


def _associate(C, mean, uv, depth, par, labels, blob_of):
    """BlockGate.distances and .assign: each marker's nearest blob (half squared Mahalanobis
    distance) where gated and likelier than clutter. Fills labels (blob -> marker) and blob_of
    (marker -> blob or -1); returns the number of pairs, or -1 where two markers want one blob
    or a distance is NaN (the NumPy path then runs the assignment solver) or a marker's block is
    not positive definite."""
    J, M = blob_of.shape[0], uv.shape[0]
    B = np.empty((3, 3))
    Lb = np.empty((3, 3))
    d = np.empty((3, 1))
    n_pairs = 0
    for j in range(J):
        blob_of[j] = -1
        for a in range(3):
            for b in range(3):
                B[a, b] = C[a * J + j, b * J + j]
        if not _cholesky(B, Lb):
            return -1
        best, best_d = 0, np.inf
        for i in range(M):
            d[0, 0] = uv[i, 0] - mean[j]
            d[1, 0] = uv[i, 1] - mean[J + j]
            d[2, 0] = depth[i] - mean[2 * J + j]
            _forward(Lb, d)
            h = 0.5 * (d[0, 0] * d[0, 0] + d[1, 0] * d[1, 0] + d[2, 0] * d[2, 0])
            if h != h:
                return -1
            if h < best_d:
                best, best_d = i, h
        c = math.log(Lb[0, 0] * Lb[1, 1] * Lb[2, 2]) + par[_GATE_CONSTANT]
        if best_d <= par[_HALF_GATE] and best_d + c < 0:
            if labels[best] >= 0:
                return -1
            labels[best] = j
            blob_of[j] = best
            n_pairs += 1
    return n_pairs


def _correct(C, mean, uv, depth, blob_of, n_pairs, q, pvw, P_out):
    """ukf.joint_correct with the associated markers' rows (axis-major, in marker order) and
    the retraction of the correction into (q, pvw); P_out gets the covariance. Returns the NIS,
    NaN where the innovation covariance is not positive definite."""
    J, n = blob_of.shape[0], 12
    m = 3 * J
    k = 3 * n_pairs
    rows = np.empty(k, dtype=np.int64)
    Ae = np.empty((k, n + 1))  # [Pyx | nu], whitened in place: L^-1 [Pyx | nu]
    r = 0
    for a in range(3):
        for j in range(J):
            b = blob_of[j]
            if b >= 0:
                rows[r] = a * J + j
                Ae[r, n] = (uv[b, a] if a < 2 else depth[b]) - mean[a * J + j]
                r += 1
    Sub = np.empty((k, k))
    for i in range(k):
        for c in range(k):
            Sub[i, c] = C[rows[i], rows[c]]
        for c in range(n):
            Ae[i, c] = C[rows[i], m + c]
    Ls = np.empty((k, k))
    if not _cholesky(Sub, Ls):
        return np.nan
    _forward(Ls, Ae)
    # [A | e]^T [A | e]: K S K^T = A^T A, the correction K nu = A^T e, the NIS e^T e
    G = np.empty((n + 1, n + 1))
    for i in range(n + 1):
        for c in range(i + 1):
            t = 0.0
            for r in range(k):
                t += Ae[r, i] * Ae[r, c]
            G[i, c] = t
            G[c, i] = t
    for i in range(n):
        for c in range(n):
            P_out[i, c] = C[m + i, m + c] - G[i, c]
    for i in range(n):
        for c in range(i):
            t = 0.5 * (P_out[i, c] + P_out[c, i])
            P_out[i, c] = t
            P_out[c, i] = t
    e = np.empty(4)
    g = np.empty(4)
    _quat_exp(G[0, n], G[1, n], G[2, n], e)
    _quat_mul(e, q, g)
    q[:] = g
    for i in range(9):
        pvw[i] += G[3 + i, n]
    return G[n, n]


def _write_state(q, pvw, out):
    """out = [R(q / |q|) row-major, p, v, w]."""
    s = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        q[i] *= s
    R = np.empty((3, 3))
    _quat_to_matrix(q, R)
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = R[i, j]
    for i in range(9):
        out[9 + i] = pvw[i]


_compiled = None


def compiled_step():
    """The compiled ``_step``, or None without numba. numba is imported and the functions
    wrapped on the first call; the compilation itself happens on the step's first call (or is
    loaded from numba's on-disk cache)."""
    global _compiled, AVAILABLE
    if not AVAILABLE:
        return None
    if _compiled is None:
        try:
            import numba
        except ImportError:  # installed but unusable (e.g. built for another NumPy)
            AVAILABLE = False
            return None
        # no fastmath: the results must equal the NumPy path's to rounding, and NaN tests work.
        # The helpers become dispatchers under their own names, which is how _step finds them;
        # numpy's error model: a division by zero gives inf or NaN as in the NumPy path (which the
        # checks then catch) instead of raising. Only _step is cached: its object code holds the
        # helpers it calls.
        module = globals()
        for name in _HELPERS:
            module[name] = numba.njit(nogil=True, error_model="numpy")(module[name])
        _compiled = numba.njit(cache=True, nogil=True, error_model="numpy")(_step)
    return _compiled


_HELPERS = (
    "_quat_exp", "_quat_mul", "_quat_of_matrix", "_quat_to_matrix", "_cholesky", "_forward",
    "_sigma_points", "_moments", "_predicted", "_all_visible", "_add_noise", "_associate",
    "_correct", "_write_state",
)  # fmt: skip
