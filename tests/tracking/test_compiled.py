"""The tracker's fast path (sigma points as columns, quaternions, block-Cholesky gating) against
the reference code it replaces on the hot path: same numbers to rounding, same associations."""

import importlib.util
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.detect.detections import Detections
from wristtrack.filter import associate as assoc
from wristtrack.filter import ukf
from wristtrack.sim.detections import acceptance_noise, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.sim.scenario_run import track_scenario
from wristtrack.tracking import compiled as fast_kernel
from wristtrack.tracking.models import (
    QUAT_TO_MATRIX,
    ConstantRateModel,
    quat_of_matrix,
    quat_to_matrix,
)
from wristtrack.tracking.tracker import Tracker, TrackerConfig, _FastStep


def test_sigma_propagator_matches_retract_propagate_lift():
    rng = np.random.default_rng(0)
    model = ConstantRateModel()
    R = Rotation.random(random_state=1).as_matrix()
    x = ConstantRateModel.initial_state(R, *rng.standard_normal((3, 3)))
    A = rng.standard_normal((12, 12)) * 0.1
    P = A @ A.T + np.eye(12) * 1e-3
    dt = 1 / 30
    sigma = ukf.SigmaColumns(model.dim, model.noise_dim)
    sigma.set_covariance(P)
    prop = model.sigma_propagator()
    out = np.empty((prop.ROWS, sigma.offsets.shape[1]))
    q_centre = prop.propagate(x, sigma.offsets, dt, quat_of_matrix(x[:9].tolist()), out)

    # the reference: the same offsets as rows, the noise scaled by its standard deviation
    offsets = sigma.offsets[:18].T.copy()
    offsets[:, 12:] *= np.sqrt(np.diag(model.process_noise(dt)))
    X = model.propagate(model.retract(x, offsets[:, :12]), offsets[:, 12:], dt)
    xi = model.lift(X[0], X)
    np.testing.assert_allclose(out[prop.LIFTS].T, xi, atol=1e-14)
    features = out[prop.FEATURES]
    np.testing.assert_allclose(features[1:10].T, X[:, 9:], atol=1e-14)
    # vec(q q^T) of each sigma point's orientation gives its rotation matrix
    np.testing.assert_allclose((QUAT_TO_MATRIX @ features[10:]).T, X[:, :9], atol=1e-14)
    centre = np.array(quat_to_matrix(q_centre)).reshape(3, 3) @ R
    np.testing.assert_allclose(centre.reshape(9), X[0, :9], atol=1e-14)


def test_quaternion_of_matrix_round_trips_at_every_angle():
    for R in Rotation.random(200, random_state=3).as_matrix():
        q = quat_of_matrix(R.reshape(9).tolist())
        np.testing.assert_allclose(np.array(quat_to_matrix(q)).reshape(3, 3), R, atol=1e-15)
    for angle in (np.pi, np.pi - 1e-9, 1e-12, 0.0):  # the branches of Shepperd's method
        for axis in np.eye(3):
            R = Rotation.from_rotvec(angle * axis).as_matrix()
            q = quat_of_matrix(R.reshape(9).tolist())
            np.testing.assert_allclose(np.array(quat_to_matrix(q)).reshape(3, 3), R, atol=1e-15)


def _random_problem(rng, J=6, M=9, spread=40.0):
    y = np.column_stack((rng.uniform(100, 500, (J, 2)), rng.uniform(0.5, 1.0, J)))
    A = rng.standard_normal((J, 3, 3)) * np.array([2.0, 2.0, 2e-3])[:, None]
    S = A @ A.swapaxes(1, 2) + np.diag([0.5, 0.5, 1e-6])
    z = y[rng.integers(0, J, M)] + rng.standard_normal((M, 3)) * np.array([spread, spread, 0.01])
    return y, S, z


def _gate_inputs(y, S, z):
    """The axis-major (3J, 3J) covariance and (3J, M) differences BlockGate takes."""
    J = len(y)
    S_full = np.zeros((3 * J, 3 * J))
    idx = np.arange(3)[:, None] * J  # row of (axis a, marker j) is a J + j
    for j in range(J):
        S_full[np.ix_((idx + j).ravel(), (idx + j).ravel())] = S[j]
    D = (z.T[:, None, :] - y.T[:, :, None]).reshape(3 * J, -1)
    return S_full, D


@pytest.mark.parametrize("spread", [0.5, 3.0, 40.0])
def test_block_gate_gives_the_reference_gnn_pairs(spread):
    params = assoc.AssociationParams()
    gate = assoc.BlockGate(6, params)
    rng = np.random.default_rng(11)
    clashes = 0
    for _ in range(200):
        y, S, z = _random_problem(rng, spread=spread)
        llr, d2 = assoc.log_likelihood_ratios(z, y, S, params)
        labels = assoc.associate_gnn(assoc.pair_scores(llr, params), assoc.gate(d2, z, params))
        expected = sorted((int(j), b) for b, j in enumerate(labels) if j >= 0)
        half_m2, constants = gate.distances(*_gate_inputs(y, S, z))
        np.testing.assert_allclose(2 * half_m2.T, d2, rtol=1e-9, atol=1e-9)
        nearest = half_m2.argmin(axis=1)
        clashes += len(set(nearest)) < len(nearest)
        assert gate.assign(half_m2, constants) == expected
    assert spread < 1 or clashes  # the clash (solver) branch was exercised


def test_block_gate_treats_a_nan_distance_as_never_gated():
    params = assoc.AssociationParams()
    gate = assoc.BlockGate(6, params)
    rng = np.random.default_rng(5)
    y, S, z = _random_problem(rng, spread=0.5)
    z[2] = np.nan
    llr, d2 = assoc.log_likelihood_ratios(z, y, S, params)
    labels = assoc.associate_gnn(assoc.pair_scores(llr, params), assoc.gate(d2, z, params))
    expected = sorted((int(j), b) for b, j in enumerate(labels) if j >= 0)
    assert gate.assign(*gate.distances(*_gate_inputs(y, S, z))) == expected


def test_block_gate_declines_a_block_that_is_not_positive_definite():
    gate = assoc.BlockGate(6, assoc.AssociationParams())
    rng = np.random.default_rng(2)
    y, S, z = _random_problem(rng)
    S[3] = -S[3]
    assert gate.distances(*_gate_inputs(y, S, z)) is None


needs_numba = pytest.mark.skipif(
    not fast_kernel.AVAILABLE, reason="numba not installed (the optional [fast] extra)"
)


@pytest.mark.parametrize(
    "compiled",
    [pytest.param(True, marks=needs_numba, id="compiled"), pytest.param(False, id="numpy")],
)
@pytest.mark.parametrize("name", ["pronation", "mix"])
def test_tracker_fast_path_matches_the_generic_path(monkeypatch, name, compiled):
    """Acceptance noise: clutter, misses, an occlusion, irregular frame intervals."""
    monkeypatch.setattr(fast_kernel, "AVAILABLE", compiled)
    steps = []
    step = _FastStep.step

    def counted(self, *args):
        out = step(self, *args)
        steps.append(out is not None)
        return out

    monkeypatch.setattr(_FastStep, "step", counted)
    fast = track_scenario(name, TrackerConfig(), seed=2)
    assert sum(steps) > 0.9 * len(fast.results)
    monkeypatch.setattr(Tracker, "_fast_step", lambda self, det: None)
    generic = track_scenario(name, TrackerConfig(), seed=2)
    for a, b in zip(fast.results, generic.results, strict=True):
        assert a.status == b.status
        np.testing.assert_array_equal(a.labels, b.labels)
        if a.has_estimate:
            np.testing.assert_allclose(a.R_ch, b.R_ch, atol=1e-12)
            np.testing.assert_allclose(a.t_ch, b.t_ch, atol=1e-12)
            np.testing.assert_allclose(a.w, b.w, atol=1e-10)
            np.testing.assert_allclose(a.cov, b.cov, rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(a.nis, b.nis, rtol=1e-9)
            assert a.nis_dof == b.nis_dof


def _fast_step_after_initialising(seed: int) -> _FastStep:
    """The fast step of a tracker initialised on a simulated recording (W0 and layout fixed)."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario("deviation", rng=rng)
    frames = simulate_detections(truth, camera, layout, acceptance_noise(len(truth.t)), rng)
    tracker = Tracker(camera, layout, TrackerConfig())
    tracker.step(frames[0].detections)
    fast = tracker._fast_step(frames[1].detections)
    assert isinstance(fast, _FastStep)
    return fast


def _random_frame(rng, obs):
    """A random state, covariance and interval, and blobs of markers near the prediction with
    misses, clutter and sometimes a blob crowding a marker (two markers then may want one)."""
    scales = np.repeat([3e-4, 4e-6, 2.5e-3, 0.09], 3)  # rad^2, m^2, (m/s)^2, (rad/s)^2
    R = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix()
    x = ConstantRateModel.initial_state(
        R, rng.normal(0, 0.03, 3), rng.normal(0, 0.2, 3), rng.normal(0, 1.0, 3)
    )
    A = rng.standard_normal((12, 12)) * np.sqrt(scales / 12)[:, None] * rng.uniform(0.1, 3)
    P = A @ A.T + np.diag(scales) * 0.05
    dt = rng.uniform(0.01, 0.07)
    moved = x.copy()
    moved[9:12] += x[12:15] * dt
    y = obs(moved[None]).reshape(6, 3)
    seen = y[rng.random(6) > 0.15] + rng.normal(0, 1, (1, 3)) * [2.0, 2.0, 3e-3]
    n = rng.poisson(3)
    cam = obs.camera
    clutter = rng.uniform([0, 0, 0.3], [cam.width, cam.height, 2.0], (n, 3))
    if rng.random() < 0.3:
        clutter = np.vstack((clutter, y[rng.integers(6)] + rng.normal(0, 1, 3) * [3, 3, 3e-3]))
    z = np.vstack((seen, clutter))
    z = z[rng.permutation(len(z))]
    return Detections(1.0, z[:, :2].copy(), z[:, 2].copy()), x, P, dt


@needs_numba
def test_compiled_step_equals_the_numpy_step_on_random_frames():
    fast = _fast_step_after_initialising(seed=7)
    assert fast._kernel is not None
    rng = np.random.default_rng(8)
    outcomes = {fast_kernel.OK: 0, fast_kernel.DECLINED: 0}
    for _ in range(400):
        det, x, P, dt = _random_frame(rng, fast.obs)
        code, *compiled = fast._kernel(x, P, dt, det.uv, det.depth, *fast._kernel_args)
        outcomes[code] += 1
        reference = fast.numpy_step(det, x, P, dt)
        stepped = fast.step(det, x, P, dt)  # what the tracker gets: declined frames go NumPy
        if code == fast_kernel.DECLINED:
            assert reference is None or all(
                np.array_equal(a, b, equal_nan=True)
                for a, b in zip(stepped, reference, strict=True)
            )
            continue
        assert reference is not None  # the compiled step never takes a frame NumPy would not
        x_c, P_c, labels, n_pairs, nis = compiled
        x_r, P_r, labels_r, n_r, nis_r, dof_r = reference
        np.testing.assert_array_equal(labels, labels_r)
        assert n_pairs == n_r and 3 * n_pairs == dof_r
        # to 1e-12 of each quantity's scale: R 1, p m, v m/s, w rad/s (up to a few), P its largest
        scale = max(1.0, np.abs(x_r[15:]).max())
        np.testing.assert_allclose(x_c[:15], x_r[:15], rtol=0, atol=1e-12)
        np.testing.assert_allclose(x_c[15:], x_r[15:], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(P_c, P_r, rtol=0, atol=1e-12 * np.abs(P_r).max())
        if n_pairs:
            assert nis == pytest.approx(nis_r, rel=1e-12)
        else:
            assert np.isnan(nis) and np.isnan(nis_r)
        for a, b in zip(stepped, (x_c, P_c, labels, n_pairs, nis, 3 * n_pairs), strict=True):
            assert np.array_equal(a, b, equal_nan=True)
    # both outcomes exercised: most frames compiled, clashing markers declined to the solver
    assert outcomes[fast_kernel.OK] > 250 and outcomes[fast_kernel.DECLINED] > 20


@needs_numba
def test_compiled_step_declines_what_only_the_numpy_path_handles():
    fast = _fast_step_after_initialising(seed=3)
    rng = np.random.default_rng(4)
    det, x, P, dt = _random_frame(rng, fast.obs)
    args = fast._kernel_args
    indefinite = P.copy()
    indefinite[4, 4] = -1e-3  # numpy_step repairs it (safe_cholesky); the kernel declines
    assert fast._kernel(x, indefinite, dt, det.uv, det.depth, *args)[0] == fast_kernel.DECLINED
    assert fast.numpy_step(det, x, indefinite, dt) is not None
    away = x.copy()
    away[:9] = Rotation.from_rotvec([np.pi, 0, 0]).as_matrix().reshape(9)  # palm turned away
    assert fast._kernel(away, P, dt, det.uv, det.depth, *args)[0] == fast_kernel.DECLINED
    assert fast.numpy_step(det, away, P, dt) is None  # the generic path takes it
    uv = det.uv.copy()
    uv[0] = np.nan
    assert fast._kernel(x, P, dt, uv, det.depth, *args)[0] == fast_kernel.DECLINED
    # blobs that are views into a wider array reach the kernel as contiguous copies
    wide = np.column_stack((det.uv, det.depth))
    strided = Detections(1.0, wide[:, :2], wide[:, 2])
    assert not strided.uv.flags.c_contiguous
    np.testing.assert_array_equal(fast.step(strided, x, P, dt)[2], fast.step(det, x, P, dt)[2])


def test_without_numba_the_numpy_path_is_selected(monkeypatch):
    monkeypatch.setitem(sys.modules, "numba", None)  # import numba now fails
    spec = importlib.util.spec_from_file_location("fast_kernel_probe", fast_kernel.__file__)
    probe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(probe)
    assert not probe.AVAILABLE and probe.compiled_step() is None
    monkeypatch.setattr(fast_kernel, "AVAILABLE", False)
    fast = _fast_step_after_initialising(seed=3)
    assert fast._kernel is None
