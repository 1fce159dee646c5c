"""Agreement statistics against hand-derived values and the literature's worked example."""

from __future__ import annotations

import numpy as np
import pytest

from wristtrack.analysis.compare.stats import (
    bland_altman,
    icc2_1,
    icc21,
    range_difference,
    rmse,
)

pytest.importorskip("pingouin")

# Shrout & Fleiss (1979) Table 2: six targets rated by four judges.
SHROUT_FLEISS = np.array([
    [9, 2, 5, 8], [6, 1, 3, 2], [8, 4, 6, 8], [7, 1, 2, 6], [10, 5, 6, 9], [6, 2, 4, 7],
], dtype=float)


def test_icc21_reproduces_shrout_and_fleiss_table_2():
    # The paper's ICC(2,1) is 0.29; from its mean squares (BMS 11.24, EMS 1.02, JMS 32.49,
    # k = 4, n = 6): (BMS - EMS) / (BMS + (k-1) EMS + k (JMS - EMS) / n) = 0.2898.
    out = icc2_1(SHROUT_FLEISS)
    assert out["icc"] == pytest.approx(0.29, abs=0.005)
    x = SHROUT_FLEISS
    n, k = x.shape
    grand = x.mean()
    bms = k * ((x.mean(axis=1) - grand) ** 2).sum() / (n - 1)
    jms = n * ((x.mean(axis=0) - grand) ** 2).sum() / (k - 1)
    resid = x - x.mean(axis=1, keepdims=True) - x.mean(axis=0) + grand
    ems = (resid**2).sum() / ((n - 1) * (k - 1))
    assert (bms, jms, ems) == pytest.approx((11.24, 32.49, 1.02), abs=0.01)
    by_hand = (bms - ems) / (bms + (k - 1) * ems + k * (jms - ems) / n)
    assert out["icc"] == pytest.approx(by_hand, abs=1e-9)
    assert out["ci95"][0] < out["icc"] < out["ci95"][1]


def test_icc21_of_two_systems_high_for_agreement_lower_for_a_bias():
    rng = np.random.default_rng(3)
    truth = rng.uniform(-40, 40, 200)
    close = icc21(truth + rng.normal(0, 0.5, 200), truth)["icc"]
    biased = icc21(truth + 15 + rng.normal(0, 0.5, 200), truth)["icc"]
    assert close > 0.999 and biased < close  # absolute agreement penalises a bias
    assert icc21(truth[:4], truth[:4])["icc"] is None  # too few targets


def test_bland_altman_by_hand():
    # d = (1, 0, 1, -1): mean 0.25, SD sqrt(2.75 / 3).
    out = bland_altman([1, 2, 3, 4, np.nan], [0, 2, 2, 5, 1])
    sd = np.sqrt(2.75 / 3)
    assert out["n"] == 4 and out["bias"] == pytest.approx(0.25)
    assert out["sd"] == pytest.approx(sd)
    assert out["loa_low"] == pytest.approx(0.25 - 1.96 * sd)
    assert out["loa_high"] == pytest.approx(0.25 + 1.96 * sd)
    assert bland_altman([1.0], [2.0])["bias"] is None


def test_rmse_and_range_difference():
    assert rmse(np.array([[3.0, 4.0], [np.nan, 0.0], [0.0, 0.0]])) == pytest.approx(
        np.sqrt(25 / 2))
    out = range_difference([0, 10, 5, np.nan], [1, 8, 3, 100])
    assert (out["range_ours"], out["range_ref"], out["error"]) == (10.0, 7.0, 3.0)
