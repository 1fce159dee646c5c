"""Kinematics against independent truth: analytic minimum-jerk reaches, monalysa as an oracle for
SPARC and log dimensionless jerk, hand-built angle and polyline data, simulator ground truth."""

import json

import numpy as np
import pytest
from monalysa.quality.smoothness import log_dimensionless_jerk as mona_ldlj
from monalysa.quality.smoothness import sparc as mona_sparc

from wristtrack.analysis import kinematics as kin
from wristtrack.analysis import motion_profiles as profiles
from wristtrack.analysis import range_of_motion as motion_range
from wristtrack.analysis import reaches as segmentation
from wristtrack.analysis import smoothness as sm
from wristtrack.analysis.kinematics_settings import KinematicsSettings
from wristtrack.cli import main
from wristtrack.errors import ConfigError, InputError
from wristtrack.geometry import quat_from_matrix
from wristtrack.io.poses import PosesWriter, read_poses, write_truth
from wristtrack.sim.motion import (
    combine,
    delay,
    min_jerk_reach,
    neutral_camera_pose,
    sample,
    scenario,
    scenario_motion,
)
from wristtrack.sim.render import render_recording
from wristtrack.sim.scenario_run import track_scenario

SETTINGS = KinematicsSettings()


def mj_speed(t, t0, T, D):
    """Analytic speed of a minimum-jerk reach of D metres over T seconds starting at t0."""
    s = np.clip((np.asarray(t) - t0) / T, 0.0, 1.0)
    return D / T * 30.0 * s**2 * (1.0 - s) ** 2


def mj_position(t, t0, T, D):
    s = np.clip((np.asarray(t) - t0) / T, 0.0, 1.0)
    return D * s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def crossing_s(fraction):
    """s in (0, 1/2) where 30 s^2 (1-s)^2 = fraction * 1.875 (the peak): from the quartic's roots,
    independently of the code under test."""
    roots = np.roots([30.0, -60.0, 30.0, 0.0, -fraction * 1.875])
    real = roots[np.abs(roots.imag) < 1e-9].real
    return float(np.min(real[(real > 0) & (real < 0.5)]))


def columns_1d(t, x, v=None):
    """Poses columns for a motion along W0 x (positions x, velocities v; v None: not estimated)."""
    zero = np.zeros_like(t)
    vx = np.full_like(t, np.nan) if v is None else v
    v0 = np.where(np.isnan(vx), np.nan, 0.0)
    return {"timestamp": t, "tx": x, "ty": zero, "tz": zero, "vx": vx, "vy": v0, "vz": v0.copy()}


# ------------------------------------------------------------------- one minimum-jerk reach


@pytest.mark.parametrize("fs", [30.0, 60.0, 120.0])
def test_minimum_jerk_reach_against_analytic_values_and_monalysa(fs):
    D, T, t0 = 0.3, 1.2, 0.8
    t = np.arange(int(round(3.0 * fs))) / fs
    cols = columns_1d(t, mj_position(t, t0, T, D), mj_speed(t, t0, T, D))
    result = kin.analyse(cols, KinematicsSettings(lowpass_hz=0.0))  # the exact samples
    assert len(result["reaches"]) == 1
    r = result["reaches"][0]
    assert r["peak_speed_m_s"] == pytest.approx(1.875 * D / T, rel=1e-12)  # t0 + T/2 is a sample
    assert r["peak_frame"] == round((t0 + T / 2) * fs)
    assert r["time_to_peak_pct"] == pytest.approx(50.0, abs=100.0 / (T * fs))  # one frame
    assert r["path_length_ratio"] == pytest.approx(1.0, abs=1e-12)
    assert r["movement_units"] == 1 and not r["truncated"]
    # Movement time between the analytic 2 % crossings, within a frame at either end.
    s = crossing_s(SETTINGS.onset_fraction)
    assert abs(r["onset_s"] - (t0 + s * T)) <= 1.0 / fs
    assert abs(r["offset_s"] - (t0 + (1 - s) * T)) <= 1.0 / fs
    # Smoothness of the segmented reach equals monalysa's on the same samples.
    v = mj_speed(t, t0, T, D)[r["start_frame"] : r["end_frame"] + 1]
    assert -1.6 <= r["sparc"] <= -1.4
    assert r["sparc"] == pytest.approx(mona_sparc(v, fs)[0], abs=1e-12)
    assert r["log_dimensionless_jerk"] == pytest.approx(mona_ldlj(v, fs, "vel"), abs=1e-12)
    # The default 6 Hz low-pass leaves a smooth reach as it is (its spectrum lies below 3 Hz).
    f = kin.analyse(cols)["reaches"][0]
    assert f["peak_frame"] == r["peak_frame"]
    assert abs(f["start_frame"] - r["start_frame"]) <= 1
    assert abs(f["end_frame"] - r["end_frame"]) <= 1
    assert f["peak_speed_m_s"] == pytest.approx(r["peak_speed_m_s"], rel=2e-3)
    assert f["sparc"] == pytest.approx(r["sparc"], abs=2e-3)
    assert f["path_length_m"] == pytest.approx(r["path_length_m"], rel=1e-3)
    assert f["movement_units"] == 1


def test_log_dimensionless_jerk_tends_to_the_analytic_value():
    # Whole pulse, finely sampled: -ln(T^3/v_peak^2 * 720 D^2/T^5) = -ln(204.8) for any D and T.
    fs, D, T = 2000.0, 0.25, 0.9
    t = np.arange(int(round(T * fs)) + 1) / fs
    v = mj_speed(t, 0.0, T, D)
    assert sm.log_dimensionless_jerk(v, fs) == pytest.approx(-np.log(204.8), abs=0.01)
    assert sm.sparc(v, fs) == pytest.approx(mona_sparc(v, fs)[0], abs=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_sparc_and_ldlj_match_monalysa_on_irregular_profiles(seed):
    rng = np.random.default_rng(seed)
    fs = float(rng.choice([25.0, 30.0, 100.0]))
    n = int(rng.integers(8, 300))
    t = np.arange(n) / fs
    pulses = [
        (rng.uniform(0, t[-1] / 2), rng.uniform(0.2, 1.0) * t[-1], rng.uniform(0.05, 0.5))
        for _ in range(3)
    ]
    v = sum(mj_speed(t, *p) for p in pulses) + np.abs(rng.normal(0, 0.01, n))
    assert sm.sparc(v, fs) == pytest.approx(mona_sparc(v, fs)[0], abs=1e-12)
    assert sm.log_dimensionless_jerk(v, fs) == pytest.approx(mona_ldlj(v, fs, "vel"), abs=1e-12)


def test_a_jerkier_movement_scores_lower():
    fs = 60.0
    t = np.arange(180) / fs
    smooth = mj_speed(t, 0.5, 1.5, 0.3)
    jerky = smooth + mj_speed(t, 1.2, 0.4, 0.05)
    assert sm.sparc(jerky, fs) < sm.sparc(smooth, fs)
    assert sm.log_dimensionless_jerk(jerky, fs) < sm.log_dimensionless_jerk(smooth, fs)


# ------------------------------------------------------------------------- segmentation


def test_two_reaches_separated_by_rest_with_mild_noise():
    fs = 30.0
    t = np.arange(int(7.0 * fs)) / fs
    pulses = ((0.7, 1.1, 0.30), (3.9, 1.5, 0.18))  # (start, duration, distance)
    x = sum(mj_position(t, *p) for p in pulses)
    v = sum(mj_speed(t, *p) for p in pulses)
    rng = np.random.default_rng(1)
    cols = columns_1d(t, x, v)
    for c in ("vx", "vy", "vz"):
        cols[c] = cols[c] + rng.normal(0.0, 0.001, t.size)  # 1 mm/s per component
    reaches = kin.analyse(cols)["reaches"]
    assert len(reaches) == 2
    for r, (t0, T, D) in zip(reaches, pulses, strict=True):
        s = crossing_s(SETTINGS.onset_fraction)
        # Truth: the first / last sample where the analytic speed is at or above the threshold.
        first = int(np.ceil((t0 + s * T) * fs - 1e-9))
        last = int(np.floor((t0 + (1 - s) * T) * fs + 1e-9))
        assert abs(r["start_frame"] - first) <= 2
        assert abs(r["end_frame"] - last) <= 2
        assert r["peak_speed_m_s"] == pytest.approx(1.875 * D / T, abs=0.005)


@pytest.mark.parametrize("seed", range(5))
def test_noise_on_the_speed_does_not_split_a_reach(seed):
    fs = 60.0
    t = np.arange(int(4.0 * fs)) / fs
    v = mj_speed(t, 1.0, 1.4, 0.3)
    noise = np.random.default_rng(seed).normal(0.0, 1.0, t.size)
    noisy = np.abs(v + 0.008 * noise)  # 8 mm/s: the 2 % threshold is 6.4 mm/s
    reaches = segmentation.segment_reaches(t, noisy, SETTINGS)
    assert len(reaches) == 1
    s, e = reaches[0]
    assert s < 1.7 * fs < e  # around the true peak
    # Wiggles well under the 20 mm/s unit rise do not add movement units.
    quieter = np.abs(v + 0.003 * noise)
    s, e = segmentation.segment_reaches(t, quieter, SETTINGS)[0]
    assert sm.movement_units(t[s : e + 1], quieter[s : e + 1]) == 1


def test_entry_threshold_ignores_rest_and_slow_drift():
    fs = 30.0
    t = np.arange(int(5.0 * fs)) / fs
    rest = np.abs(np.random.default_rng(0).normal(0.0, 0.01, t.size))  # up to ~4 cm/s at rest
    assert segmentation.segment_reaches(t, rest, SETTINGS) == []
    slow = mj_speed(t, 1.0, 2.0, 0.08)  # peak 7.5 cm/s: above entry, below min peak speed
    assert segmentation.segment_reaches(t, slow, SETTINGS) == []
    short = KinematicsSettings(min_duration_s=3.0)
    assert segmentation.segment_reaches(t, mj_speed(t, 1.0, 1.2, 0.3), short) == []


def test_a_gap_ends_a_reach():
    fs = 30.0
    t = np.arange(int(3.5 * fs)) / fs
    t0, T, D = 0.8, 1.5, 0.4
    x = mj_position(t, t0, T, D)
    v = mj_speed(t, t0, T, D)
    gap = slice(int((t0 + 0.6 * T) * fs), int((t0 + 0.6 * T) * fs) + 4)  # after the peak
    x[gap] = np.nan
    v[gap] = np.nan
    result = kin.analyse(columns_1d(t, x, v), KinematicsSettings(lowpass_hz=0.0))
    r1, r2 = result["reaches"]
    assert r1["end_frame"] == gap.start - 1 and r1["truncated"]
    assert r2["start_frame"] == gap.stop and r2["truncated"]
    assert r1["movement_units"] == 1
    # beyond the gap the hand is slowing down: that segment's peak is its first sample
    assert r2["peak_speed_m_s"] == pytest.approx(v[gap.stop])
    # the whole run's path leaves out the stretch hidden by the gap
    jump = x[gap.stop] - x[gap.start - 1]
    assert result["path_length_m"] == pytest.approx(D - jump, abs=1e-12)


def test_two_overlapping_pulses_are_one_reach_with_two_units():
    fs = 100.0
    t = np.arange(int(3.0 * fs)) / fs
    one = (0.5, 1.0, 0.25)
    two = (1.1, 1.0, 0.25)  # starts before the first ends: speed dips but not to rest
    x = mj_position(t, *one) + mj_position(t, *two)
    v = mj_speed(t, *one) + mj_speed(t, *two)
    reaches = kin.analyse(columns_1d(t, x, v))["reaches"]
    assert len(reaches) == 1
    assert reaches[0]["movement_units"] == 2
    s, e = reaches[0]["start_frame"], reaches[0]["end_frame"]
    assert sm.movement_units(t[s : e + 1], mj_speed(t, *one)[s : e + 1]) == 1


def test_movement_units_rise_and_interval_rules():
    fs = 200.0
    t = np.arange(int(2.0 * fs)) / fs
    base = mj_speed(t, 0.2, 1.2, 0.3)
    # a bump of peak 15 mm/s: under the 20 mm/s rise, not a unit
    small = base + mj_speed(t, 1.0, 0.3, 0.015 * 0.3 / 1.875)
    assert sm.movement_units(t, small) == 1
    # two 60 mm/s bumps 100 ms apart count once (peaks < 150 ms apart), 300 ms apart twice
    bump = (0.06 * 0.1 / 1.875,)
    close = mj_speed(t, 0.5, 0.1, *bump) + mj_speed(t, 0.6, 0.1, *bump)
    apart = mj_speed(t, 0.5, 0.1, *bump) + mj_speed(t, 0.8, 0.1, *bump)
    assert sm.movement_units(t, close) == 1
    assert sm.movement_units(t, apart) == 2


# ----------------------------------------------------------------- RoM, path length, speeds


def test_range_of_motion_of_hand_built_angles():
    nan = np.nan
    angles = np.array([
        [nan, 5.0, nan],
        [2.0, -30.0, nan],
        [-7.5, 60.0, nan],
        [4.0, nan, nan],
        [nan, 10.0, nan],
    ])
    rom = motion_range.range_of_motion(angles)
    assert rom["deviation"] == {
        "min_deg": -7.5, "max_deg": 4.0, "range_deg": 11.5, "start_deg": 2.0, "end_deg": 4.0
    }
    assert rom["flexion"] == {
        "min_deg": -30.0, "max_deg": 60.0, "range_deg": 90.0, "start_deg": 5.0, "end_deg": 10.0
    }
    assert all(v is None for v in rom["pronation"].values())


def test_path_length_of_a_polyline_with_a_gap():
    p = np.array([
        [0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 4.0, 12.0],  # 5 + 12
        [np.nan] * 3,  # gap: no line from (3, 4, 12) to (10, 0, 0)
        [10.0, 0.0, 0.0], [10.0, 0.0, 1.0],  # 1
        [np.nan, 0.0, 0.0],  # one unknown coordinate is a gap too
        [20.0, 0.0, 0.0],
    ])
    assert profiles.path_length(p) == pytest.approx(18.0, abs=1e-12)
    t = np.arange(len(p)) * 0.1
    cols = {"timestamp": t, "tx": p[:, 0], "ty": p[:, 1], "tz": p[:, 2]}
    assert kin.analyse(cols)["path_length_m"] == pytest.approx(18.0, abs=1e-12)


def test_speed_falls_back_to_differences_and_angular_speed_to_quaternions():
    tr, _, _ = scenario("reach", fps=60.0)
    q = quat_from_matrix(tr.R_rel)
    speed = profiles.speed_profile(tr.t, tr.p_rel)  # no velocity: central differences
    truth = np.linalg.norm(tr.v, axis=1)
    assert np.max(np.abs(speed - truth)) < 0.01 * truth.max()
    rate = profiles.angular_speed_profile(tr.t, q)
    w_truth = np.linalg.norm(tr.w, axis=1)
    assert np.max(np.abs(rate - w_truth)) < 0.01 * w_truth.max()
    # Given and finite velocities are used as they are; a missing one is filled in.
    v = tr.v.copy()
    v[10] = np.nan
    mixed = profiles.speed_profile(tr.t, tr.p_rel, v)
    np.testing.assert_array_equal(np.delete(mixed, 10), np.delete(truth, 10))
    assert mixed[10] == pytest.approx(truth[10], abs=1e-4)
    # Unknown positions are gaps even if a velocity is present.
    p = tr.p_rel.copy()
    p[20] = np.nan
    assert np.isnan(profiles.speed_profile(tr.t, p, tr.v)[20])


def test_lowpass_passes_slow_motion_stops_fast_noise_and_respects_gaps():
    fs = 60.0
    t = np.arange(600) / fs
    slow, fast = np.sin(2 * np.pi * 1.0 * t), np.sin(2 * np.pi * 15.0 * t)
    out = profiles.lowpass(t, slow + fast, 6.0)
    inner = slice(60, -60)  # away from the ends' transients
    assert np.max(np.abs(out[inner] - slow[inner])) < 0.03  # 1 Hz through, 15 Hz to 2.6 % (-32 dB)
    # 3 dB down at the cutoff, in phase (Winter's dual-pass correction; without it, 6 dB)
    at_cutoff = profiles.lowpass(t, np.sin(2 * np.pi * 6.0 * t), 6.0)
    np.testing.assert_allclose(at_cutoff[inner], np.sin(2 * np.pi * 6.0 * t[inner]) / np.sqrt(2),
                               atol=0.01)
    # Each run between gaps is filtered on its own: what happens after a gap does not leak back.
    x = slow.copy()
    x[300:305] = np.nan
    y = x.copy()
    y[305:] += 5.0
    fx, fy = profiles.lowpass(t, x, 6.0), profiles.lowpass(t, y, 6.0)
    assert np.isnan(fx[300:305]).all()
    np.testing.assert_array_equal(fx[:300], fy[:300])
    # Irregular timing (jitter, dropped frames): resampled, so a smooth signal stays as it is.
    rng = np.random.default_rng(0)
    ti = np.sort(rng.choice(t, 450, replace=False)) + rng.uniform(-0.004, 0.004, 450)
    si = np.sin(2 * np.pi * 1.0 * ti)
    assert np.max(np.abs(profiles.lowpass(ti, si, 6.0)[40:-40] - si[40:-40])) < 0.01


def test_metrics_of_a_tracked_reach_agree_with_its_truth(tmp_path):
    """The measurement-level tracker on the simulated reach (acceptance noise): its filtered
    velocities are noisy, the 6 Hz low-pass makes the reach metrics those of the truth."""
    run = track_scenario("reach", seed=3)
    with PosesWriter(tmp_path / "poses.csv") as writer:
        for result in run.results:
            writer.write_result(result)
    write_truth(tmp_path / "truth.csv", run.truth)
    (got,) = kin.analyse_file(tmp_path / "poses.csv")["reaches"]
    (want,) = kin.analyse_file(tmp_path / "truth.csv")["reaches"]
    assert abs(got["start_frame"] - want["start_frame"]) <= 2
    assert abs(got["end_frame"] - want["end_frame"]) <= 2
    assert got["peak_speed_m_s"] == pytest.approx(want["peak_speed_m_s"], rel=0.05)
    assert got["path_length_m"] == pytest.approx(want["path_length_m"], rel=0.05)
    assert got["sparc"] == pytest.approx(want["sparc"], abs=0.05)
    assert got["movement_units"] == want["movement_units"] == 1
    # speed_series gives the figures the speed the reaches were measured on, and the raw one
    columns = read_poses(tmp_path / "poses.csv")
    raw, analysed = kin.speed_series(columns)
    assert analysed[got["peak_frame"]] == got["peak_speed_m_s"]
    v = np.linalg.norm(np.column_stack([columns[c] for c in ("vx", "vy", "vz")]), axis=1)
    known = np.isfinite(v)
    np.testing.assert_array_equal(raw[known], v[known])


# ----------------------------------------------------------------- simulated end to end


def _analytic_reach(motion, fraction):
    """Peak speed and 2 %-crossing movement time of a scenario's reach, from its analytic
    trajectory densely sampled (10 kHz), not from the recording's frames."""
    R_c0, t_c0 = neutral_camera_pose()
    dense = sample(motion, np.arange(0.0, motion.duration, 1e-4), R_c0, t_c0)
    speed = np.linalg.norm(dense.v, axis=1)
    above = np.flatnonzero(speed >= fraction * speed.max())
    return speed.max(), dense.t[above[-1]] - dense.t[above[0]]


@pytest.mark.parametrize("name", ["reach", "mix"])
def test_simulated_scenario_through_truth_csv(name, tmp_path):
    tr, _, _ = scenario(name, rng=4)  # "mix": jittered timing and dropped frames
    write_truth(tmp_path / "truth.csv", tr)  # the columns exactly as read_poses gives them
    result = kin.analyse(read_poses(tmp_path / "truth.csv"))
    json.dumps(result, allow_nan=False)
    assert len(result["reaches"]) == 1
    r = result["reaches"][0]
    peak, movement_time = _analytic_reach(scenario_motion(name)[0], SETTINGS.onset_fraction)
    frame = float(np.median(np.diff(tr.t)))
    assert r["peak_speed_m_s"] == pytest.approx(peak, rel=0.05)
    assert abs(r["movement_time_s"] - movement_time) <= 2 * frame
    assert -1.6 <= r["sparc"] <= -1.3
    assert r["path_length_ratio"] == pytest.approx(1.0, abs=1e-6)
    assert r["movement_units"] == 1
    truth_rom = np.degrees(tr.angles)
    assert result["range_of_motion"]["flexion"]["min_deg"] == pytest.approx(
        truth_rom[:, 1].min(), abs=1e-6
    )


def test_two_delayed_reaches_from_the_simulator_segment_into_two():
    motion = combine(
        min_jerk_reach(0.25, 1.0, (1.0, 0.0, 0.0), 0.5),
        delay(min_jerk_reach(0.2, 1.3, (0.0, 1.0, 0.0), 0.5), 2.5),
    )
    R_c0, t_c0 = neutral_camera_pose()
    tr = sample(motion, np.arange(0.0, motion.duration, 1 / 30), R_c0, t_c0)
    cols = {
        "timestamp": tr.t, **{f"t{a}": tr.p_rel[:, i] for i, a in enumerate("xyz")},
        **{f"v{a}": tr.v[:, i] for i, a in enumerate("xyz")},
    }
    reaches = kin.analyse(cols)["reaches"]
    assert len(reaches) == 2
    s = crossing_s(SETTINGS.onset_fraction)
    for r, (T, D) in zip(reaches, ((1.0, 0.25), (1.3, 0.2)), strict=True):
        assert abs(r["movement_time_s"] - T * (1 - 2 * s)) <= 2 / 30
        assert r["path_length_m"] == pytest.approx(D, rel=0.02)  # the 2 % tails hold ~0.1 %


# ------------------------------------------------------------------------------ errors


def test_empty_and_untracked_runs_give_json_ready_results():
    t = np.arange(5) * 0.1
    nan = np.full(5, np.nan)
    cols = {
        "timestamp": t, "tx": nan, "ty": nan, "tz": nan, "vx": nan, "vy": nan, "vz": nan,
        "qw": nan, "qx": nan, "qy": nan, "qz": nan, "wx": nan, "wy": nan, "wz": nan,
        "deviation_deg": nan, "flexion_deg": nan, "pronation_deg": nan,
    }
    result = kin.analyse(cols)
    json.dumps(result, allow_nan=False)
    assert result["reaches"] == [] and result["speed"]["peak_m_s"] is None
    assert result["duration_s"] == pytest.approx(0.4)
    empty = kin.analyse({k: np.array([]) for k in cols})
    assert empty["path_length_m"] == 0.0 and empty["duration_s"] == 0.0


def test_bad_input_raises_one_line_errors(tmp_path):
    with pytest.raises(ConfigError, match="onset_fraction"):
        KinematicsSettings(onset_fraction=2.0)
    with pytest.raises(ConfigError, match="min_duration_s"):
        KinematicsSettings(min_duration_s=-1.0)
    with pytest.raises(InputError, match="lack tx"):
        kin.analyse({"timestamp": np.zeros(3)})
    t = np.array([0.0, 0.1, 0.1, 0.3])
    with pytest.raises(InputError, match="row 2"):
        kin.analyse({"timestamp": t, "tx": t, "ty": t, "tz": t})
    bad = tmp_path / "poses.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="poses.csv"):
        kin.analyse_file(bad)
    with pytest.raises(InputError, match="SPARC"):
        sm.sparc(np.array([1.0]), 30.0)


def test_track_writes_kinematics_of_poses_csv_and_prints_the_reaches(tmp_path, capsys):
    rec = render_recording(tmp_path / "rec", "reach", seed=2, n_frames=4)  # too short to reach
    out = tmp_path / "run"
    assert main(["track", str(rec), "--out", str(out), "--no-progress", "--no-report"]) == 0
    assert capsys.readouterr().out.splitlines()[-1].split() == ["reaches", "none", "detected"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kinematics"] == kin.analyse_file(out / "poses.csv")
    assert "range_of_motion" in summary and "frames" in summary  # the contract keys stay


def test_console_line_of_the_reaches():
    tr, _, _ = scenario("reach")
    cols = {"timestamp": tr.t, **{f"t{a}": tr.p_rel[:, i] for i, a in enumerate("xyz")}}
    line = kin.format_reaches(kin.analyse(cols))
    assert line.split()[:3] == ["reaches", "1", "detected:"]
    numbers = [float(w.rstrip(",")) for w in line.split() if w[0].isdigit()]
    assert numbers[0] == 1
    assert numbers[1] == pytest.approx(1.875 * 0.3 / 1.2, abs=0.002)  # central differences
    assert numbers[2] == pytest.approx(1.2 * (1 - 2 * crossing_s(0.02)), abs=2 / 30)
