"""The paper's model with roll-pitch-yaw angles (issue 12 item 4): regular at the neutral pose
where the Z-Y-Z state is singular, the same motion equations, continuous through its twin."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from wristtrack.geometry import matrix_from_euler
from wristtrack.sim.scenario_run import track_scenario
from wristtrack.tracking.models import MODELS, PaperModel, PaperRPYModel, continuous_euler
from wristtrack.tracking.tracker import Status, TrackerConfig


def test_rpy_state_is_regular_at_neutral_where_zyz_is_not():
    turned = Rotation.from_euler("X", -0.01).as_matrix()  # a 0.6 degree pronation
    for model, expected in ((PaperRPYModel(), 0.01), (PaperModel(), 2.0)):
        x = model.initial_state(np.eye(3), np.zeros(3))
        step = np.linalg.norm(model.lift(x, model.initial_state(turned, np.zeros(3))[None])[0])
        if model.proper:
            assert step > expected  # Z-Y-Z: two angles jump by about pi/2
        else:
            assert abs(step - expected) < 1e-9  # roll-pitch-yaw: exactly the rotation


def test_rpy_propagation_follows_the_paper_equations():
    model = PaperRPYModel()
    R0 = Rotation.from_euler("ZYX", [0.3, 0.5, -0.2]).as_matrix()
    x = model.initial_state(R0, np.array([0.1, 0.2, 0.3]), np.array([1.0, 0.0, -1.0]))
    n = np.array([[0.5, 0.0, 0.0, 0.2, -0.1, 0.3]])
    out = model.propagate(x[None], n, 0.05)[0]
    np.testing.assert_allclose(out[:3], [0.15, 0.2, 0.25])
    expected = R0 @ Rotation.from_rotvec(n[0, 3:] * 0.05).as_matrix()
    np.testing.assert_allclose(Rotation.from_euler("ZYX", out[6:]).as_matrix(), expected,
                               atol=1e-12)
    np.testing.assert_allclose(model.pose(out[None])[0][0], expected, atol=1e-12)


def test_tait_bryan_twin_is_the_same_rotation_and_the_nearer_one_is_kept():
    rng = np.random.default_rng(0)
    e = rng.uniform([-3, -1.4, -3], [3, 1.4, 3], (50, 3))
    twin = e + np.array([np.pi, 0.0, np.pi])
    twin[:, 1] = np.pi - e[:, 1]
    np.testing.assert_allclose(matrix_from_euler(twin, "ZYX"), matrix_from_euler(e, "ZYX"),
                               atol=1e-12)
    picked = continuous_euler(e, twin + 0.01, proper=False)  # near the twin: the twin
    np.testing.assert_allclose(picked, twin, atol=1e-12)


def test_the_tracker_runs_the_rpy_paper_model():
    assert MODELS["paper_rpy"] is PaperRPYModel
    run = track_scenario("flexion", TrackerConfig.paper(model="paper_rpy"), seed=0)
    assert run.results[-1].status == Status.TRACKING
    assert run.errors.orientation_rmse_deg < 20.0  # the paper's method, not ours: no depth
