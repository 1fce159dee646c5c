"""The tracker's step for the default configuration written as plain loops, for numba.

The same filter as the generic path (tracking/generic_step.py, the reference, which reads like
the paper): augmented UKF prediction with the measurement, one-to-one (GNN) association with a
chi-square gate and Cholesky correction, for the constant-rate model, with or without the skin
slide in the state (tracking/slide_model.py) and the depth map's offset after it
(tracking/offset_model.py), with pixel + depth measurements (and the noise the markers share:
skin slide, misregistration) on a camera with or without lens distortion.
A frame's arrays are tiny (37 sigma points and a 12-D tangent, 45 and 14-D with the slide, 53
and 16-D with the offset too; 6 markers x 3 measurements), so in NumPy the per-call overhead is
nearly all the cost; compiled (tracking/compiled.py), the frame is one call. Equal to the
generic step to rounding (tests/tracking/test_compiled.py).

Only the common frame is handled here. ``step`` returns DECLINED, having changed nothing, where
the generic path has a branch this does not copy: a covariance that is not positive definite
(its Cholesky fallbacks), a marker out of view, a NaN distance or two markers wanting one blob
(the assignment solver), a marker without a blob crowding one with a blob (the blob may show
both: tracking/merged.py). The tracker then runs the generic path on the same frame.

The quaternion helpers are geometry's (``*_into``) and the depth noise is
depth_noise.depth_sigma and oblique_sigma: compiled.py compiles those very functions with these.
"""

from __future__ import annotations

import math

import numpy as np

from wristtrack.camera import distorted
from wristtrack.depth_noise import depth_sigma, oblique_sigma
from wristtrack.geometry import (
    quat_exp_into,
    quat_mul_into,
    quat_of_rotation_into,
    rotation_of_quat_into,
)
from wristtrack.tracking.kernel_algebra import cholesky_into, forward_solve_into, moments_into
from wristtrack.tracking.kernel_camera import rolling_shift, skin_slope
from wristtrack.tracking.merged import may_merge

OK = 0  # the frame is done: the outputs are valid
DECLINED = 1  # the generic path must take this frame (see the module's docstring)

# Layout of the ``par`` vector of constants (built by ``compiled.frame_constants``).
(
    _SCALE, _FX, _FY, _CX, _CY, _U_MAX, _V_MAX, _PIXEL_VAR, _DEPTH_COEFF, _DEPTH_FLOOR,
    _DEPTH_OFFSET, _DEPTH_Z0, _SQRT_QA, _SQRT_QW, _FACING_COS, _GATE_CONSTANT, _HALF_GATE,
    _REGISTRATION_PX, _GRAZING_COS, _MERGE_REACH, _DEPTH_OBLIQUE, _SLIDE_TAU, _DISTORTED,
    _N_OFFSET, _SQRT_DRIFT, _OFFSET_GRAZING_COS, _DEPTH_DELAY, _READOUT, _N_SCALARS,
) = range(29)  # fmt: skip
_SLIDE_VAR = _N_SCALARS  # the slide's stationary variances (3)
_DIST = _SLIDE_VAR + 3  # the lens distortion, Camera's (k1, k2, p1, p2, k3, k4, k5, k6)
_N_PAR = _DIST + 8


# --------------------------------------------------------------------------- the step


def step(x, P, dt, uv, depth, blob_var, layout, slide, sliding, R_c0, t_c0, wm, wc, par):
    """One tracking frame: (code, x, P, labels, markers associated, NIS); see the module.

    x (18,) state [R row-major, p, v, w] and P (12, 12) its tangent covariance, or with the skin
    slide in the state (tracking/slide_model.py) x (18 + k,) [..., s] and P (12 + k, 12 + k), s
    the slide along the hand's first k axes (observation.STATE_SLIDE_AXES), and the depth offset
    (du, dv) after it where par[_N_OFFSET] is 2 (tracking/offset_model.py); dt the step;
    uv (M, 2) and depth (M,) the blobs (all depths finite), blob_var (M,) the pixel variance
    each blob adds to its marker's in the update (generic_step._blob_variance); layout (J, 3) the
    markers in the hand frame; slide (J, 3) each marker's share in the common skin slide taken
    as noise (MarkerObservation.slide); sliding (J,) 1 for the markers the state's slide moves,
    else 0; R_c0, t_c0 the camera pose of W0; wm, wc (S,) the unscented weights, S = 37 (+ 4 k
    with the slide, + 8 with the offset) sigma points ordered 0, +columns of L, -columns of L,
    +noise, -noise (the weights of all but the first are equal, so this is ukf.sigma_offsets'
    set); par the constants (``compiled.frame_constants``).
    """
    n, M, m = P.shape[0], uv.shape[0], 3 * layout.shape[0]
    labels = np.empty(M, dtype=np.int64)
    for i in range(M):
        labels[i] = -1
    x_out = np.empty(x.shape[0])
    P_out = np.empty((n, n))
    L = np.empty((n, n))
    if not cholesky_into(P, L):
        return DECLINED, x_out, P_out, labels, 0, np.nan

    # predict: W holds one row per sigma point, columns [0, m) its measurements, axis-major
    # (u of each marker, then v, then z), columns [m, m + n) its lift about the propagated centre
    qs = np.empty(4)  # the state's orientation
    qc = np.empty(4)  # the centre's turn over dt
    W = np.empty((wm.shape[0], m + n))
    _sigma_points(x, L, dt, layout, sliding, R_c0, t_c0, par, qs, qc, W)
    mean = np.empty(m + n)
    C = np.empty((m + n, m + n))
    moments_into(W, wm, wc, mean, C)
    q = np.empty(4)  # the predicted orientation, pvw its p, v, w, sl its slide (zeros: none),
    pvw = np.empty(9)  # ro its depth offset (zeros: none)
    sl = np.zeros(3)
    ro = np.zeros(2)
    _predicted(x, dt, mean[m:], qs, qc, par, q, pvw, sl, ro)
    placed = np.empty(layout.shape)  # the predicted markers in the hand frame, slid
    for j in range(layout.shape[0]):
        for i in range(3):
            placed[j, i] = layout[j, i] + sliding[j] * sl[i]
    Rc = np.empty((3, 3))  # the predicted hand's camera-frame pose
    tc = np.empty(3)
    _camera_pose(q, pvw, R_c0, t_c0, Rc, tc)
    facing = np.empty(layout.shape[0])
    if not _all_visible(Rc, tc, placed, par, facing):
        return DECLINED, x_out, P_out, labels, 0, np.nan

    # associate
    _add_noise(C, mean, facing, par)  # C's measurement block: Pyy + each blob's noise
    blob_of = np.empty(layout.shape[0], dtype=np.int64)
    n_pairs = _associate(C, mean, uv, depth, par, labels, blob_of)
    if n_pairs < 0 or may_merge(Rc, tc, placed, mean, blob_of, par[_MERGE_REACH]):
        return DECLINED, x_out, P_out, labels, 0, np.nan
    _add_shared_noise(C, Rc, tc, placed, slide, par)  # and now Pyy + R

    # update
    nis = np.nan
    if n_pairs == 0:  # coasting: the prediction
        for i in range(n):
            for j in range(n):
                P_out[i, j] = 0.5 * (C[m + i, m + j] + C[m + j, m + i])
    else:
        nis = _correct(C, mean, uv, depth, blob_var, blob_of, n_pairs, q, pvw, sl, ro, P_out,
                       par)
        if nis != nis:
            return DECLINED, x_out, P_out, labels, 0, np.nan
    _write_state(q, pvw, sl, ro, par, x_out)
    return OK, x_out, P_out, labels, n_pairs, nis


def _sigma_points(x, L, dt, layout, sliding, R_c0, t_c0, par, qs, qc, W):
    """The augmented sigma points retracted, propagated, measured and lifted (the rows of W),
    as ConstantRateModel.retract, propagate and lift (SlidingSkinModel's where n > 12,
    DepthOffsetModel's with the offset) and MarkerObservation.__call__; qs, qc get the state's
    orientation and the centre's turn."""
    J, n, S = layout.shape[0], L.shape[0], W.shape[0]
    m = 3 * J
    n_off = int(par[_N_OFFSET])  # the depth offset's states, after the slide's (n_sl)
    n_sl = n - 12 - n_off
    nq = (S - 1) // 2 - n  # noise dimensions: accelerations (6), the slide's, the offset's
    s_drift = par[_SQRT_DRIFT] * math.sqrt(dt)  # the offset's drift over dt per unit noise
    ro = np.zeros(2)  # a point's depth offset (px)
    nc = np.empty(3)  # and the hand's normal, camera frame
    keep = math.exp(-dt / par[_SLIDE_TAU])  # the slide's share left after dt
    sq_s = np.empty(3)  # its innovation's sigmas
    for i in range(3):
        sq_s[i] = math.sqrt(par[_SLIDE_VAR + i] * (1.0 - keep * keep))
    sp = np.zeros(3)  # a point's slide, propagated, along the hand's axes
    delay = par[_DEPTH_DELAY]  # the depth frame's capture after the colour's (s)
    readout = par[_READOUT]  # a rolling shutter's, top row to bottom (s)
    vs, ws = np.empty(3), np.empty(3)  # the sigma point's velocity and angular velocity (W0)
    scale = par[_SCALE]
    sqdt = math.sqrt(dt)
    sa_v = par[_SQRT_QA] * sqdt  # velocity change per unit noise offset: sqrt(q_a / dt) dt
    sa_p = 0.5 * sa_v * dt  # position change: sqrt(q_a / dt) dt^2 / 2
    sw_w = par[_SQRT_QW] * sqdt
    sw_turn = 0.5 * sw_w * dt  # the midpoint rate's share of the turn
    quat_of_rotation_into(x, qs)
    quat_exp_into(x[15] * dt, x[16] * dt, x[17] * dt, qc)  # the centre turns by w dt
    qc[1:] = -qc[1:]  # conj(q_centre): sigma rotations relative to the centre's
    off = np.empty(n + nq)  # the sigma point's tangent offset and noise offset
    r = np.empty(4)
    t = np.empty(4)
    tr = np.empty(4)
    o = np.empty(4)
    R = np.empty((3, 3))
    for s in range(S):
        # 0, +scale L[:, k], -scale L[:, k], +noise, -noise (noise in units of its sigma)
        for i in range(n + nq):
            off[i] = 0.0
        if 1 <= s <= n:
            for i in range(n):
                off[i] = scale * L[i, s - 1]
        elif n < s <= 2 * n:
            for i in range(n):
                off[i] = -scale * L[i, s - 1 - n]
        elif 2 * n < s <= 2 * n + nq:
            off[s - 1 - n] = scale
        elif s > 2 * n + nq:
            off[s - 1 - n - nq] = -scale
        # lifts of p, v, w (and s): the propagated point minus the propagated centre (the
        # state cancels)
        for i in range(3):
            W[s, m + 3 + i] = off[3 + i] + dt * off[6 + i] + sa_p * off[n + i]
            W[s, m + 6 + i] = off[6 + i] + sa_v * off[n + i]
            W[s, m + 9 + i] = off[9 + i] + sw_w * off[n + 3 + i]
        for i in range(n_sl):
            W[s, m + 12 + i] = keep * off[12 + i] + sq_s[i] * off[n + 6 + i]
            sp[i] = keep * x[18 + i] + W[s, m + 12 + i]
        for i in range(n_off):
            W[s, m + 12 + n_sl + i] = off[12 + n_sl + i] + s_drift * off[n + 6 + n_sl + i]
            ro[i] = x[18 + n_sl + i] + W[s, m + 12 + n_sl + i]
        # orientation t r q_state: retraction r = exp(dphi), turn t = exp(dt (w + dw) + the
        # midpoint share of the angular acceleration)
        quat_exp_into(off[0], off[1], off[2], r)
        quat_exp_into(
            dt * (x[15] + off[9]) + sw_turn * off[n + 3],
            dt * (x[16] + off[10]) + sw_turn * off[n + 4],
            dt * (x[17] + off[11]) + sw_turn * off[n + 5],
            t,
        )
        quat_mul_into(t, r, tr)
        quat_mul_into(tr, qs, o)
        # log of the rotation relative to the centre's, t r conj(q_centre) (right for either
        # sign of its w: a w < 0 quaternion is the same rotation as -q, whose angle is < pi)
        quat_mul_into(tr, qc, r)
        nv = math.sqrt(1e-300 * r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3])
        k = 2.0 * math.atan(nv / r[0]) / nv
        for i in range(3):
            W[s, m + i] = r[1 + i] * k
        # the markers seen from the camera: R_c0 (R(o) T_j + p') + t_c0, projected
        rotation_of_quat_into(o, R)
        px = x[9] + dt * x[12] + W[s, m + 3]
        py = x[10] + dt * x[13] + W[s, m + 4]
        pz = x[11] + dt * x[14] + W[s, m + 5]
        for i in range(3 if n_off or delay else 0):
            nc[i] = R_c0[i, 0] * R[0, 2] + R_c0[i, 1] * R[1, 2] + R_c0[i, 2] * R[2, 2]
        if delay or readout:  # the sigma point's rates, W0
            for i in range(3):
                vs[i] = x[12 + i] + W[s, m + 6 + i]
                ws[i] = x[15 + i] + W[s, m + 9 + i]
        for j in range(J):
            a = layout[j, 0] + sliding[j] * sp[0]
            b = layout[j, 1] + sliding[j] * sp[1]
            c = layout[j, 2] + sliding[j] * sp[2]
            hx = R[0, 0] * a + R[0, 1] * b + R[0, 2] * c + px
            hy = R[1, 0] * a + R[1, 1] * b + R[1, 2] * c + py
            hz = R[2, 0] * a + R[2, 1] * b + R[2, 2] * c + pz
            X = R_c0[0, 0] * hx + R_c0[0, 1] * hy + R_c0[0, 2] * hz + t_c0[0]
            Y = R_c0[1, 0] * hx + R_c0[1, 1] * hy + R_c0[1, 2] * hz + t_c0[1]
            Z = R_c0[2, 0] * hx + R_c0[2, 1] * hy + R_c0[2, 2] * hz + t_c0[2]
            W[s, j], W[s, J + j] = _pixel(X, Y, Z, par)
            if readout:  # seen where it is when a rolling shutter reads the row it is on
                du, dv = rolling_shift(R_c0, vs, ws, hx - px, hy - py, hz - pz, X, Y, Z,
                                       W[s, J + j], par[_FX], par[_FY], par[_V_MAX] + 0.5, readout)
                W[s, j] += du
                W[s, J + j] += dv
            W[s, 2 * J + j] = Z
            if n_off or delay:
                slope = skin_slope(X, Y, Z, nc[0], nc[1], nc[2], par[_OFFSET_GRAZING_COS])
            if n_off:  # its depth read off the blob, on the skin's slope
                W[s, 2 * J + j] += slope * (nc[0] * ro[0] / par[_FX] + nc[1] * ro[1] / par[_FY])
            if delay:  # in a depth frame captured delay after the colour: the skin moved
                ra, rb, rc = hx - px, hy - py, hz - pz  # delay n.(v + w x R a) along n
                towards = (R[0, 2] * (vs[0] + ws[1] * rc - ws[2] * rb)
                           + R[1, 2] * (vs[1] + ws[2] * ra - ws[0] * rc)
                           + R[2, 2] * (vs[2] + ws[0] * rb - ws[1] * ra))
                W[s, 2 * J + j] -= delay * towards * slope / Z
    qc[1:] = -qc[1:]


def _pixel(X, Y, Z, par):
    """Camera.project of the camera-frame point (X, Y, Z): (u, v)."""
    x, y = X / Z, Y / Z
    if par[_DISTORTED] != 0.0:
        d = _DIST
        x, y = distorted(x, y, par[d], par[d + 1], par[d + 2], par[d + 3], par[d + 4],
                         par[d + 5], par[d + 6], par[d + 7])
    return par[_FX] * x + par[_CX], par[_FY] * y + par[_CY]


def _predicted(x, dt, lift, qs, qc, par, q, pvw, sl, ro):
    """The predicted state: the mean lift retracted about the propagated centre."""
    g = np.empty(4)
    e = np.empty(4)
    quat_mul_into(qc, qs, g)
    quat_exp_into(lift[0], lift[1], lift[2], e)
    quat_mul_into(e, g, q)
    for i in range(3):
        pvw[i] = x[9 + i] + dt * x[12 + i] + lift[3 + i]
        pvw[3 + i] = x[12 + i] + lift[6 + i]
        pvw[6 + i] = x[15 + i] + lift[9 + i]
    keep = math.exp(-dt / par[_SLIDE_TAU])
    n_off = int(par[_N_OFFSET])
    n_sl = lift.shape[0] - 12 - n_off
    for i in range(n_sl):
        sl[i] = keep * x[18 + i] + lift[12 + i]
    for i in range(n_off):
        ro[i] = x[18 + n_sl + i] + lift[12 + n_sl + i]


def _camera_pose(q, pvw, R_c0, t_c0, Rc, tc):
    """The hand's camera-frame pose (Rc, tc) of the state (q, pvw) relative to W0."""
    R = np.empty((3, 3))
    rotation_of_quat_into(q, R)
    for i in range(3):
        for j in range(3):
            Rc[i, j] = R_c0[i, 0] * R[0, j] + R_c0[i, 1] * R[1, j] + R_c0[i, 2] * R[2, j]
        tc[i] = R_c0[i, 0] * pvw[0] + R_c0[i, 1] * pvw[1] + R_c0[i, 2] * pvw[2] + t_c0[i]


def _all_visible(Rc, tc, layout, par, facing):
    """generic_step.expected_markers for all markers of the hand at (Rc, tc): in front, facing
    the camera, on the sensor; ``facing`` (J,) gets the cosines between the hand's normal and
    their lines of sight."""
    for j in range(layout.shape[0]):
        a, b, c = layout[j, 0], layout[j, 1], layout[j, 2]
        X = Rc[0, 0] * a + Rc[0, 1] * b + Rc[0, 2] * c + tc[0]
        Y = Rc[1, 0] * a + Rc[1, 1] * b + Rc[1, 2] * c + tc[1]
        Z = Rc[2, 0] * a + Rc[2, 1] * b + Rc[2, 2] * c + tc[2]
        if not Z > 0:
            return False
        facing[j] = -(X * Rc[0, 2] + Y * Rc[1, 2] + Z * Rc[2, 2]) / math.sqrt(X * X + Y * Y + Z * Z)
        u, v = _pixel(X, Y, Z, par)
        if not (facing[j] > par[_FACING_COS] and -0.5 <= u < par[_U_MAX]
                and -0.5 <= v < par[_V_MAX]):
            return False
    return True


def _add_noise(C, mean, facing, par):
    """MarkerObservation.noise_variance added to the measurement block's diagonal, the markers
    seen at ``facing`` (cosines, _all_visible's)."""
    J = facing.shape[0]
    for i in range(2 * J):
        C[i, i] += par[_PIXEL_VAR]
    for j in range(J):
        z = mean[2 * J + j]
        sd = depth_sigma(z, par[_DEPTH_COEFF], par[_DEPTH_FLOOR], par[_DEPTH_OFFSET],
                         par[_DEPTH_Z0]) + oblique_sigma(z, facing[j], par[_DEPTH_OBLIQUE])
        C[2 * J + j, 2 * J + j] += sd * sd


def _add_shared_noise(C, Rc, tc, layout, slide, par):
    """MarkerObservation.noise_covariance's shared part, G G^T with G its slide_jacobian and
    registration_jacobian at the predicted hand pose (Rc, tc), added to the measurement block
    (rows axis-major)."""
    J = layout.shape[0]
    G = np.zeros((3 * J, 5))
    s_reg = par[_REGISTRATION_PX]
    for j in range(J):
        a, b, c = layout[j, 0], layout[j, 1], layout[j, 2]
        X = Rc[0, 0] * a + Rc[0, 1] * b + Rc[0, 2] * c + tc[0]
        Y = Rc[1, 0] * a + Rc[1, 1] * b + Rc[1, 2] * c + tc[1]
        Z = Rc[2, 0] * a + Rc[2, 1] * b + Rc[2, 2] * c + tc[2]
        for i in range(3):  # the skin slide along hand axis i
            s = slide[j, i]
            if s == 0.0:
                continue
            dx, dy, dz = Rc[0, i] * s, Rc[1, i] * s, Rc[2, i] * s
            u_plus, v_plus = _pixel(X + dx, Y + dy, Z + dz, par)
            u_minus, v_minus = _pixel(X - dx, Y - dy, Z - dz, par)
            G[j, i] = 0.5 * (u_plus - u_minus)
            G[J + j, i] = 0.5 * (v_plus - v_minus)
            G[2 * J + j, i] = dz
        # the misregistration: the surface plane's depth one sigma off the blob in u and in v
        slope = skin_slope(X, Y, Z, Rc[0, 2], Rc[1, 2], Rc[2, 2], par[_GRAZING_COS])
        G[2 * J + j, 3] = s_reg * Rc[0, 2] * slope / par[_FX]
        G[2 * J + j, 4] = s_reg * Rc[1, 2] * slope / par[_FY]
    for r in range(3 * J):
        for c in range(r + 1):
            t = 0.0
            for i in range(5):
                t += G[r, i] * G[c, i]
            C[r, c] += t
            if c != r:
                C[c, r] += t


def _associate(C, mean, uv, depth, par, labels, blob_of):
    """associate.gate and associate_gnn for full measurements: each marker's nearest blob (half
    squared Mahalanobis distance) where gated and likelier than clutter. Nearest blobs that are
    all different are the optimal assignment (each marker has its own minimum), so the solver
    is only needed when markers compete. Fills labels (blob -> marker) and blob_of (marker ->
    blob or -1); returns the number of pairs, or -1 where two markers want one blob or a
    distance is NaN (the generic path then runs the assignment solver) or a marker's block is
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
        if not cholesky_into(B, Lb):
            return -1
        best, best_d = 0, np.inf
        for i in range(M):
            d[0, 0] = uv[i, 0] - mean[j]
            d[1, 0] = uv[i, 1] - mean[J + j]
            d[2, 0] = depth[i] - mean[2 * J + j]
            forward_solve_into(Lb, d)
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


def _correct(C, mean, uv, depth, blob_var, blob_of, n_pairs, q, pvw, sl, ro, P_out, par):
    """ukf.update with the associated markers' rows (axis-major, in marker order), their
    blobs' pixel rows raised by blob_var, and the retraction of the correction into (q, pvw, sl,
    ro); P_out gets the covariance. Returns the NIS, NaN where the innovation covariance is not
    positive definite."""
    J, n = blob_of.shape[0], P_out.shape[0]
    m = 3 * J
    k = 3 * n_pairs
    rows = np.empty(k, dtype=np.int64)
    extra = np.zeros(k)  # each row's own addition to the noise
    Ae = np.empty((k, n + 1))  # [Pyx | nu], whitened in place: L^-1 [Pyx | nu]
    r = 0
    for a in range(3):
        for j in range(J):
            b = blob_of[j]
            if b >= 0:
                rows[r] = a * J + j
                Ae[r, n] = (uv[b, a] if a < 2 else depth[b]) - mean[a * J + j]
                if a < 2:
                    extra[r] = blob_var[b]
                r += 1
    Sub = np.empty((k, k))
    for i in range(k):
        for c in range(k):
            Sub[i, c] = C[rows[i], rows[c]]
        Sub[i, i] += extra[i]
        for c in range(n):
            Ae[i, c] = C[rows[i], m + c]
    Ls = np.empty((k, k))
    if not cholesky_into(Sub, Ls):
        return np.nan
    forward_solve_into(Ls, Ae)
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
    quat_exp_into(G[0, n], G[1, n], G[2, n], e)
    quat_mul_into(e, q, g)
    q[:] = g
    for i in range(9):
        pvw[i] += G[3 + i, n]
    n_off = int(par[_N_OFFSET])
    for i in range(n - 12 - n_off):
        sl[i] += G[12 + i, n]
    for i in range(n_off):
        ro[i] += G[n - n_off + i, n]
    return G[n, n]


def _write_state(q, pvw, sl, ro, par, out):
    """out = [R(q / |q|) row-major, p, v, w] (and the slide s and the depth offset where out
    has room for them)."""
    s = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        q[i] *= s
    R = np.empty((3, 3))
    rotation_of_quat_into(q, R)
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = R[i, j]
    for i in range(9):
        out[9 + i] = pvw[i]
    n_off = int(par[_N_OFFSET])
    n_sl = out.shape[0] - 18 - n_off
    for i in range(n_sl):
        out[18 + i] = sl[i]
    for i in range(n_off):
        out[18 + n_sl + i] = ro[i]


# the functions ``step`` calls, compiled under these names before it (compiled._jit)
HELPERS = (
    "quat_exp_into", "quat_mul_into", "quat_of_rotation_into", "rotation_of_quat_into",
    "depth_sigma", "oblique_sigma", "distorted", "cholesky_into", "forward_solve_into",
    "_sigma_points", "skin_slope", "rolling_shift", "_pixel", "moments_into", "_predicted",
    "_camera_pose", "_all_visible", "may_merge", "_add_noise", "_add_shared_noise", "_associate",
    "_correct", "_write_state",
)  # fmt: skip
