"""Pose errors against truth (analysis/pose_errors.py), against hand-derived values."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.analysis.pose_errors import rmse_net_of_constant_errors


def test_the_constant_part_of_an_error_is_what_evaluate_takes_out():
    """Poses off by a constant rotation and offset plus known per-frame noise: net of the
    constant parts, the RMS errors are the noise's (hand-derived from the draws)."""
    rng = np.random.default_rng(2)
    n = 3000
    R_true = Rotation.random(n, random_state=3).as_matrix()
    t_true = rng.normal(0, 0.1, (n, 3)) + [0, 0, 0.6]
    E = Rotation.from_rotvec([0.01, -0.02, 0.005])  # ~1.3 deg, constant
    wobble = Rotation.from_rotvec(rng.normal(0, np.radians(0.2), (n, 3)))
    R_est = (wobble * E).as_matrix() @ R_true
    shake = rng.normal(0, 2e-4, (n, 3))
    t_est = t_true + [0.004, -0.002, 0.003] + shake
    pos, rot = rmse_net_of_constant_errors(R_est, t_est, R_true, t_true)
    shake -= shake.mean(axis=0)
    assert pos == pytest.approx(np.sqrt(np.mean(np.sum(shake**2, axis=1))) * 1e3, rel=0.01)
    assert rot == pytest.approx(np.degrees(np.sqrt(np.mean(wobble.magnitude() ** 2))), rel=0.02)
