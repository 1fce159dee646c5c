"""wristtrack.geometry against independent oracles (scipy Rotation, scipy.linalg.expm, numpy)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from wristtrack import geometry as g
from wristtrack.hand import HandLayout

TAIT_BRYAN = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
PROPER = ["XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ"]
ALL_SEQUENCES = TAIT_BRYAN + PROPER


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240531)


def random_rotations(shape: tuple[int, ...], seed: int = 7) -> Rotation:
    n = int(np.prod(shape))
    return Rotation.random(n, random_state=seed)


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def twist_matrix(xi: np.ndarray) -> np.ndarray:
    """4x4 se(3) matrix of xi = (rho, phi), built by hand (no wristtrack code)."""
    rho, (x, y, z) = xi[:3], xi[3:]
    return np.array([[0, -z, y, rho[0]], [z, 0, -x, rho[1]], [-y, x, 0, rho[2]], [0, 0, 0, 0]])


# ------------------------------------------------------------------------------------ skew, vee


def test_skew_is_cross_product_batched(rng):
    w, v = rng.normal(size=(2, 4, 5, 3))
    S = g.skew(w)
    assert S.shape == (4, 5, 3, 3)
    np.testing.assert_allclose((S @ v[..., None])[..., 0], np.cross(w, v), atol=1e-14)
    np.testing.assert_allclose(S, -np.swapaxes(S, -1, -2))
    np.testing.assert_allclose(g.vee(S), w, atol=0)


# ------------------------------------------------------------------------------------ so3 exp/log


def test_so3_exp_matches_scipy_batched(rng):
    phi = rng.normal(size=(3, 7, 3)) * 1.5
    expected = Rotation.from_rotvec(phi.reshape(-1, 3)).as_matrix().reshape(3, 7, 3, 3)
    np.testing.assert_allclose(g.so3_exp(phi), expected, atol=1e-14)


def test_so3_log_matches_scipy_batched():
    r = random_rotations((6, 50))
    R = r.as_matrix().reshape(6, 50, 3, 3)
    phi = g.so3_log(R)
    assert phi.shape == (6, 50, 3)
    np.testing.assert_allclose(phi, r.as_rotvec().reshape(6, 50, 3), atol=1e-13)
    assert np.all(np.linalg.norm(phi, axis=-1) <= np.pi)


def test_so3_round_trips():
    R = random_rotations((200,)).as_matrix()
    np.testing.assert_allclose(g.so3_exp(g.so3_log(R)), R, atol=1e-14)


@pytest.mark.parametrize(
    "theta", [0.0, 1e-300, 1e-15, 1e-12, 1e-9, 1e-6, 1e-4, 1e-3, 0.0099999, 0.0100001, 0.3]
)
def test_so3_small_angles(rng, theta):
    axes = unit(rng.normal(size=(20, 3)))
    phi = theta * axes
    R_ref = Rotation.from_rotvec(phi).as_matrix()
    np.testing.assert_allclose(g.so3_exp(phi), R_ref, rtol=0, atol=5e-16)
    # Rotation vector stays accurate relative to the matrix precision (no 0/0, no NaN).
    got = g.so3_log(R_ref)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, phi, rtol=0, atol=1e-15 + 1e-13 * theta)


def test_so3_exp_of_exact_zero_is_identity():
    np.testing.assert_array_equal(
        g.so3_exp(np.zeros((2, 3))), np.broadcast_to(np.eye(3), (2, 3, 3))
    )
    np.testing.assert_array_equal(g.so3_log(np.eye(3)), np.zeros(3))


@pytest.mark.parametrize("gap", [1e-3, 1e-6, 1e-9, 1e-12])
def test_so3_log_near_pi_keeps_axis_sign(rng, gap):
    axes = unit(rng.normal(size=(50, 3)))
    theta = np.pi - gap
    R = Rotation.from_rotvec(theta * axes).as_matrix()
    phi = g.so3_log(R)
    # Axis sign is determined by the (tiny) antisymmetric part: must be +axis, not -axis.
    np.testing.assert_allclose(phi, theta * axes, rtol=0, atol=1e-12)
    np.testing.assert_allclose(phi, Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.so3_exp(phi), R, atol=1e-14)


def test_so3_log_exactly_pi(rng):
    axes = unit(rng.normal(size=(50, 3)))
    # R = 2 n n^T - I, a half turn, built by hand.
    R = 2 * axes[:, :, None] * axes[:, None, :] - np.eye(3)
    phi = g.so3_log(R)
    np.testing.assert_allclose(np.linalg.norm(phi, axis=-1), np.pi, atol=1e-14)
    # Either sign is a valid answer at exactly pi.
    same = np.minimum(
        np.abs(phi - np.pi * axes).max(axis=-1), np.abs(phi + np.pi * axes).max(axis=-1)
    )
    assert same.max() < 1e-13
    np.testing.assert_allclose(g.so3_exp(phi), R, atol=1e-14)
    for k, diag in enumerate(([1, -1, -1], [-1, 1, -1], [-1, -1, 1])):
        expected = np.zeros(3)
        expected[k] = np.pi
        np.testing.assert_allclose(np.abs(g.so3_log(np.diag(diag))), expected, atol=0)


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, 3, elements=st.floats(-3.0, 3.0)))
def test_so3_exp_log_property(phi):
    phi = phi * min(1.0, (np.pi - 1e-6) / max(np.linalg.norm(phi), 1e-300))
    np.testing.assert_allclose(g.so3_log(g.so3_exp(phi)), phi, atol=1e-12)


def test_rotation_angle_and_distance():
    r = random_rotations((30,))
    np.testing.assert_allclose(g.rotation_angle(r.as_matrix()), r.magnitude(), atol=1e-14)
    a, b = r[:15], r[15:]
    np.testing.assert_allclose(
        g.rotation_distance(a.as_matrix(), b.as_matrix()), (a.inv() * b).magnitude(), atol=1e-13
    )


def test_project_to_so3(rng):
    R = random_rotations((10,)).as_matrix()
    noisy = R + 1e-3 * rng.normal(size=R.shape)
    P = g.project_to_so3(noisy)
    np.testing.assert_allclose(
        P @ np.swapaxes(P, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-14
    )
    np.testing.assert_allclose(np.linalg.det(P), 1.0, atol=1e-14)
    np.testing.assert_allclose(P, R, atol=5e-3)
    # A reflection is mapped to a proper rotation.
    assert np.linalg.det(g.project_to_so3(np.diag([1.0, 1.0, -1.0]))) > 0


@pytest.mark.parametrize("theta", [0.0, 1e-7, 0.005, 0.5, 2.0, np.pi - 1e-6])
def test_left_jacobian_numerically(rng, theta):
    phi = theta * unit(rng.normal(size=3))
    J = g.so3_left_jacobian(phi)
    # exp(phi + h d) = exp(J h d) exp(phi) to first order: compare finite differences.
    h = 1e-6
    for d in np.eye(3):
        lhs = Rotation.from_rotvec(phi + h * d) * Rotation.from_rotvec(phi).inv()
        np.testing.assert_allclose(lhs.as_rotvec() / h, J @ d, atol=1e-5)
    np.testing.assert_allclose(g.so3_left_jacobian_inv(phi) @ J, np.eye(3), atol=1e-10)


# ------------------------------------------------------------------------------------ quaternions


def test_quat_from_matrix_matches_scipy_and_sign_convention():
    r = random_rotations((500,))
    q = g.quat_from_matrix(r.as_matrix().reshape(5, 100, 3, 3))
    assert q.shape == (5, 100, 4)
    assert np.all(q[..., 0] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    ref = r.as_quat(canonical=True, scalar_first=True).reshape(5, 100, 4)
    np.testing.assert_allclose(q, ref, atol=1e-15)


def test_quat_sign_convention_near_and_at_half_turn(rng):
    axes = unit(rng.normal(size=(20, 3)))
    for theta in (np.pi - 1e-9, np.pi):
        r = Rotation.from_rotvec(theta * axes)
        q = g.quat_from_matrix(r.as_matrix())
        assert np.all(q[..., 0] >= 0)
        np.testing.assert_allclose(g.matrix_from_quat(q), r.as_matrix(), atol=1e-14)
    q = g.quat_from_matrix(np.diag([-1.0, 1.0, -1.0]))
    np.testing.assert_allclose(q, [0, 0, 1, 0], atol=0)


def test_matrix_from_quat_normalises_and_ignores_sign(rng):
    q = rng.normal(size=(40, 4))
    ref = Rotation.from_quat(q, scalar_first=True).as_matrix()
    np.testing.assert_allclose(g.matrix_from_quat(3.7 * q), ref, atol=1e-15)
    np.testing.assert_allclose(g.matrix_from_quat(-q), ref, atol=1e-15)
    qu = unit(q) * np.sign(q[:, :1])
    np.testing.assert_allclose(g.quat_from_matrix(g.matrix_from_quat(q)), qu, atol=1e-14)


# ------------------------------------------------------------------------------------ Euler angles


@pytest.mark.parametrize("seq", ALL_SEQUENCES)
def test_matrix_from_euler_matches_scipy(rng, seq):
    angles = rng.uniform(-np.pi, np.pi, size=(4, 25, 3))
    ref = Rotation.from_euler(seq, angles.reshape(-1, 3)).as_matrix().reshape(4, 25, 3, 3)
    np.testing.assert_allclose(g.matrix_from_euler(angles, seq), ref, atol=1e-15)


@pytest.mark.parametrize("seq", ALL_SEQUENCES)
def test_euler_from_matrix_matches_scipy(seq):
    r = random_rotations((300,), seed=3)
    R = r.as_matrix().reshape(3, 100, 3, 3)
    got = g.euler_from_matrix(R, seq)
    assert got.shape == (3, 100, 3)
    ref = r.as_euler(seq).reshape(3, 100, 3)
    np.testing.assert_allclose(wrap(got - ref), 0, atol=1e-12)
    np.testing.assert_allclose(g.matrix_from_euler(got, seq), R, atol=1e-14)
    # scipy's ranges: middle in [-pi/2, pi/2] (Tait-Bryan) or [0, pi] (proper).
    lo, hi = (0.0, np.pi) if seq in PROPER else (-np.pi / 2, np.pi / 2)
    assert np.all((got[..., 1] >= lo - 1e-15) & (got[..., 1] <= hi + 1e-15))
    assert np.all(np.abs(got) <= np.pi)


@pytest.mark.parametrize("seq", ["xyz", "zyx", "zyz", "yzx"])
def test_extrinsic_lowercase_like_scipy(rng, seq):
    angles = rng.uniform(-1.5, 1.5, size=(10, 3))
    R = g.matrix_from_euler(angles, seq)
    np.testing.assert_allclose(R, Rotation.from_euler(seq, angles).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(
        wrap(g.euler_from_matrix(R, seq) - Rotation.from_matrix(R).as_euler(seq)), 0, atol=1e-12
    )


def _singular_middles(seq: str) -> list[float]:
    return [0.0, np.pi] if seq[0] == seq[2] else [np.pi / 2, -np.pi / 2]


@pytest.mark.parametrize("seq", ["YZX", "ZYZ", "ZYX"])
@pytest.mark.parametrize("delta", [1e-7, 3e-8, 1e-9, 1e-11])
def test_euler_near_gimbal_lock(rng, seq, delta):
    for singular in _singular_middles(seq):
        # Step into the valid range of the middle angle.
        middle = singular + delta if singular in (0.0, -np.pi / 2) else singular - delta
        n = 30
        angles = np.column_stack([rng.uniform(-3, 3, n), np.full(n, middle), rng.uniform(-3, 3, n)])
        R = Rotation.from_euler(seq, angles).as_matrix()  # oracle matrix
        got = g.euler_from_matrix(R, seq)
        assert np.all(np.isfinite(got))
        # The decomposition reproduces the matrix to machine precision right next to the lock
        # (scipy's as_euler collapses within 1e-7 and is off by up to ~delta there).
        np.testing.assert_allclose(Rotation.from_euler(seq, got).as_matrix(), R, atol=1e-14)
        np.testing.assert_allclose(got[:, 1], middle, atol=1e-12)
        if delta >= 1e-9:
            # Individual angles are still determined, with error ~ 1e-16 / delta.
            np.testing.assert_allclose(wrap(got - angles), 0, atol=1e-6)


@pytest.mark.parametrize("seq", ["YZX", "ZYZ", "ZYX", "XYX", "XZY"])
def test_euler_at_exact_gimbal_lock_like_scipy(rng, seq):
    for singular in _singular_middles(seq):
        angles = np.column_stack(
            [rng.uniform(-1.5, 1.5, 20), np.full(20, singular), rng.uniform(-1.5, 1.5, 20)]
        )
        R = Rotation.from_euler(seq, angles).as_matrix()
        got = g.euler_from_matrix(R, seq)
        # Whole rotation on the first angle, 0 on the third.
        np.testing.assert_array_equal(got[:, 2], 0.0)
        np.testing.assert_allclose(got[:, 1], singular, atol=1e-12)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            ref = Rotation.from_matrix(R).as_euler(seq)
        np.testing.assert_allclose(wrap(got - ref), 0, atol=1e-12)
        np.testing.assert_allclose(g.matrix_from_euler(got, seq), R, atol=1e-14)


@pytest.mark.parametrize("bad", ["XY", "XXY", "XYY", "XyZ", "ABC", "XYZX"])
def test_bad_euler_sequence(bad):
    with pytest.raises(ValueError):
        g.matrix_from_euler(np.zeros(3), bad)
    with pytest.raises(ValueError):
        g.euler_from_matrix(np.eye(3), bad)


# ------------------------------------------------------------------------------------ wrist angles


def test_sequence_constants():
    assert g.ISB_WRIST_SEQUENCE == "YZX"
    assert g.PAPER_EULER_SEQUENCE == "ZYZ"


def test_wrist_angles_against_scipy(rng):
    """The raw intrinsic Y-Z-X decomposition (left-hand signs) against SciPy; a right hand's
    deviation and pronation are the same angles negated."""
    n = 200
    a_z = rng.uniform(-0.6, 0.6, n)
    a_y = rng.uniform(-1.4, 1.4, n)
    a_x = rng.uniform(-3.0, 3.0, n)
    R = Rotation.from_euler("YZX", np.column_stack([a_y, a_z, a_x])).as_matrix()
    got = g.wrist_angles(R.reshape(10, 20, 3, 3), "left")
    assert got.shape == (10, 20, 3)
    np.testing.assert_allclose(got.reshape(n, 3), np.column_stack([a_z, a_y, a_x]), atol=1e-13)
    right = g.wrist_angles(R, "right")
    np.testing.assert_allclose(right, np.column_stack([-a_z, a_y, -a_x]), atol=1e-13)
    for side in g.HAND_SIDES:
        dev, flex, pron = g.wrist_angles(R, side).T
        np.testing.assert_allclose(g.matrix_from_wrist_angles(dev, flex, pron, side), R,
                                   atol=1e-14)


@pytest.mark.parametrize("side", ["right", "left"])
def test_wrist_angle_signs_mean_the_same_on_both_hands(side):
    """ISB signs from the anatomy of the layout itself: ulnar deviation turns the fingers
    towards the little finger (MCP5), palmar flexion towards the palm (-Z), pronation turns
    the thumb (CMC1) towards the palm."""
    layout = HandLayout.default() if side == "right" else HandLayout.default().mirrored()
    assert layout.side == side
    thumb_y, little_y = layout.marker("CMC1")[1], layout.marker("MCP5")[1]
    a = 0.4
    ulnar = Rotation.from_rotvec([0, 0, np.sign(little_y) * a]).as_matrix()
    palmar = Rotation.from_rotvec([0, a, 0]).as_matrix()
    pronation = Rotation.from_rotvec([-np.sign(thumb_y) * a, 0, 0]).as_matrix()
    assert (ulnar @ [1, 0, 0])[1] * little_y > 0  # fingers towards the little finger
    assert (palmar @ [1, 0, 0])[2] < 0  # fingers towards the palm
    assert (pronation @ layout.marker("CMC1"))[2] < 0  # thumb towards the palm
    np.testing.assert_allclose(g.wrist_angles(ulnar, side), [a, 0, 0], atol=1e-15)
    np.testing.assert_allclose(g.wrist_angles(palmar, side), [0, a, 0], atol=1e-15)
    np.testing.assert_allclose(g.wrist_angles(pronation, side), [0, 0, a], atol=1e-15)
    # Order of composition: flexion first (outermost), then deviation, then pronation.
    np.testing.assert_allclose(
        g.matrix_from_wrist_angles(a, a, a, side), palmar @ ulnar @ pronation, atol=1e-15
    )


def test_unknown_side_is_refused():
    with pytest.raises(ValueError, match="hand side"):
        g.wrist_angles(np.eye(3), "up")


def test_matrix_from_wrist_angles_broadcasts():
    R = g.matrix_from_wrist_angles(np.zeros((4, 1)), np.linspace(-1, 1, 5), 0.2)
    assert R.shape == (4, 5, 3, 3)
    np.testing.assert_allclose(
        g.wrist_angles(R)[..., 1], np.broadcast_to(np.linspace(-1, 1, 5), (4, 5)), atol=1e-14
    )


# ------------------------------------------------------------------------------------ SE(3)


def test_se3_exp_matches_expm(rng):
    xi = rng.normal(size=(40, 6)) * np.array([0.5, 0.5, 0.5, 1.0, 1.0, 1.0])
    T = g.se3_exp(xi.reshape(4, 10, 6))
    assert T.shape == (4, 10, 4, 4)
    ref = np.stack([expm(twist_matrix(x)) for x in xi]).reshape(4, 10, 4, 4)
    np.testing.assert_allclose(T, ref, atol=1e-13)


@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-8, 1e-3, 0.5, 2.5, np.pi - 1e-6, np.pi - 1e-9])
def test_se3_log_round_trip(rng, theta):
    rho = rng.normal(size=(20, 3))
    phi = theta * unit(rng.normal(size=(20, 3)))
    xi = np.concatenate([rho, phi], axis=-1)
    T = g.se3_exp(xi)
    np.testing.assert_allclose(T, np.stack([expm(twist_matrix(x)) for x in xi]), atol=1e-12)
    np.testing.assert_allclose(g.se3_log(T), xi, atol=1e-9 if theta > 3 else 1e-12)
    np.testing.assert_allclose(g.se3_exp(g.se3_log(T)), T, atol=1e-13)


def test_se3_pure_translation():
    xi = np.array([0.1, -0.2, 0.3, 0, 0, 0])
    T = g.se3_exp(xi)
    np.testing.assert_array_equal(T[:3, :3], np.eye(3))
    np.testing.assert_allclose(T[:3, 3], xi[:3], atol=0)
    np.testing.assert_allclose(g.se3_log(T), xi, atol=0)


def test_pose_helpers(rng):
    r = random_rotations((12,))
    R = r.as_matrix().reshape(3, 4, 3, 3)
    t = rng.normal(size=(3, 4, 3))
    T = g.make_pose(R, t)
    assert T.shape == (3, 4, 4, 4)
    np.testing.assert_array_equal(T[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], (3, 4, 4)))
    np.testing.assert_allclose(g.pose_inverse(T), np.linalg.inv(T), atol=1e-14)
    np.testing.assert_allclose(
        g.pose_compose(T, g.pose_inverse(T)), np.broadcast_to(np.eye(4), T.shape), atol=1e-14
    )
    # make_pose broadcasts a single translation over many rotations.
    assert g.make_pose(R, np.zeros(3)).shape == (3, 4, 4, 4)


def test_transform_points_against_scipy_apply(rng):
    r = random_rotations((5,))
    t = rng.normal(size=(5, 3))
    p = rng.normal(size=(5, 6, 3))
    got = g.transform_points(r.as_matrix(), t, p)
    assert got.shape == (5, 6, 3)
    for b in range(5):
        np.testing.assert_allclose(got[b], r[b].apply(p[b]) + t[b], atol=1e-14)
    # One pose applied to a plain (N,3) cloud.
    np.testing.assert_allclose(
        g.transform_points(r[0].as_matrix(), t[0], p[0]), r[0].apply(p[0]) + t[0], atol=1e-14
    )


def test_relative_pose(rng):
    r0, r = random_rotations((2,), seed=11)
    t_c0 = rng.normal(size=3)
    t_rel = rng.normal(size=3)
    R_ch = (r0 * r).as_matrix()
    t_ch = t_c0 + r0.apply(t_rel)
    R, t = g.relative_pose(r0.as_matrix(), t_c0, R_ch, t_ch)
    np.testing.assert_allclose(R, r.as_matrix(), atol=1e-14)
    np.testing.assert_allclose(t, t_rel, atol=1e-14)
    # Same thing as inv(T_c0) @ T_ch.
    T = np.linalg.inv(g.make_pose(r0.as_matrix(), t_c0)) @ g.make_pose(R_ch, t_ch)
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-14)
    np.testing.assert_allclose(T[:3, 3], t, atol=1e-14)


# ---------------------------------------------------- single-quaternion helpers (compiled step)


def _quat(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    g.quat_of_rotation_into(R.reshape(9), q)
    return q


def _matrix(q: np.ndarray) -> np.ndarray:
    R = np.empty((3, 3))
    g.rotation_of_quat_into(q, R)
    return R


def test_quat_of_rotation_into_round_trips_and_agrees_with_scipy_at_every_angle():
    rotations = list(Rotation.random(200, random_state=3).as_matrix())
    for angle in (np.pi, np.pi - 1e-9, 1e-12, 0.0):  # each branch of Shepperd's method
        rotations += [Rotation.from_rotvec(angle * axis).as_matrix() for axis in np.eye(3)]
    for R in rotations:
        q = _quat(R)
        np.testing.assert_allclose(_matrix(q), R, atol=1e-15)
        ref = Rotation.from_matrix(R).as_quat(scalar_first=True)
        assert abs(q @ ref) == pytest.approx(1.0, abs=1e-14)  # the same rotation, either sign


def test_quat_exp_and_mul_into_compose_like_rotation_matrices(rng):
    for _ in range(100):
        a, b = rng.normal(0, 1.5, (2, 3))
        qa, qb, qab = np.empty(4), np.empty(4), np.empty(4)
        g.quat_exp_into(*a, qa)
        g.quat_exp_into(*b, qb)
        g.quat_mul_into(qa, qb, qab)
        np.testing.assert_allclose(_matrix(qa), expm(g.skew(a)), atol=1e-14)
        np.testing.assert_allclose(_matrix(qab), expm(g.skew(a)) @ expm(g.skew(b)), atol=1e-14)
    q = np.empty(4)
    g.quat_exp_into(0.0, 0.0, 0.0, q)  # exact at zero, no division by zero
    np.testing.assert_array_equal(q, [1.0, 0.0, 0.0, 0.0])
