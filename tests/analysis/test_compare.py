"""``wristtrack compare`` on synthetic data with planted values (no rendering): a run folder
built from a scripted motion's exact poses, and a reference that saw the same motion in its
own lab frame, at its own rate, on its own clock."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack.analysis.compare.comparison import compare, comparison_json
from wristtrack.cli import main
from wristtrack.errors import InputError
from wristtrack.geometry import rotation_distance
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.markers.trajectories import MarkerTrajectories
from wristtrack.io.markers.trc import write_trc
from wristtrack.io.poses import read_poses, write_truth
from wristtrack.report.comparison import write_comparison_html
from wristtrack.sim.motion import Trajectory, sample, scenario_motion, timestamps

pytest.importorskip("pingouin")

R_LC = Rotation.from_euler("xyz", [20.0, -150.0, 40.0], degrees=True).as_matrix()
T_LC = np.array([0.8, 1.2, 0.9])
OFFSET, RATIO, RATE = 0.731, 1.0003, 120.0
CLUSTER = np.array([[0.03, 0.02, 0.015], [0.07, 0.01, 0.02], [0.05, -0.025, 0.018]])  # hand


def _run(folder, traj: Trajectory, layout: HandLayout, noise=None):
    folder.mkdir()
    if noise is not None:
        traj = noise(traj)
    write_truth(folder / "poses.csv", traj)
    summary = {"range_of_motion": {}, "hand_layout": layout.to_dict(),
               "conventions": {"side": "right"}}
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def _reference(path, motion, R_c0, t_c0, layout, duration, noise_mm=0.0, seed=0):
    tau = np.arange(0.0, OFFSET + RATIO * duration + 0.4, 1.0 / RATE)
    t_cam = np.clip((tau - OFFSET) / RATIO, 0.0, motion.duration)
    R_rel, p_rel = motion.pose(t_cam)
    R_ch, t_ch = R_c0 @ R_rel, p_rel @ R_c0.T + t_c0
    pts = np.concatenate([CLUSTER, layout.points])
    lab = (np.einsum("nij,kj->nki", R_ch, pts) + t_ch[:, None]) @ R_LC.T + T_LC
    lab += np.random.default_rng(seed).normal(0, noise_mm * 1e-3, lab.shape)
    names = ("C1", "C2", "C3", *(f"Subj:{n}" for n in MARKER_NAMES))
    write_trc(path, MarkerTrajectories(names, np.arange(len(tau)), tau, lab, RATE, False, "t"),
              "mm")
    return path


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """(run folder, reference TRC, truth trajectory) of the 'mix' motion (every axis and a
    reach) at 30 fps; the reference noise-free."""
    root = tmp_path_factory.mktemp("compare")
    motion, (R_c0, t_c0) = scenario_motion("mix")
    traj = sample(motion, timestamps(int(motion.duration * 30) + 1, 30.0), R_c0, t_c0)
    layout = HandLayout.default()
    run = _run(root / "run", traj, layout)
    ref = _reference(root / "ref.trc", motion, R_c0, t_c0, layout, traj.t[-1])
    return run, ref, traj


MAP = ",".join(f"{n}={n}" for n in MARKER_NAMES)


def _transform_errors(result):
    R = np.array(result["registration"]["rotation"])
    t = np.array(result["registration"]["translation"])
    c = np.array(result["registration"]["hand_centre_cam_m"])
    ang = float(np.degrees(rotation_distance(R, R_LC)))
    return ang, float(np.linalg.norm((R - R_LC) @ c + t - T_LC) * 1e3)


@pytest.mark.parametrize("mode", ["markers", "cluster"])
def test_exact_poses_recover_the_planted_clock_and_transform(scene, mode):
    run, ref, _ = scene
    kw = {"markers": MAP} if mode == "markers" else {"cluster": "C1,C2,C3"}
    r = compare(run, ref, **kw).result
    assert abs(r["time_offset_s"] - OFFSET) < 2e-4
    assert abs(r["clock_ratio"] - RATIO) < 2e-5
    ang, mm = _transform_errors(r)
    assert ang < 0.01 and mm < 0.05
    assert r["pos_rmse_mm"] < 0.05 and r["rot_rmse_deg"] < 0.02
    for axis in ("deviation", "flexion", "pronation"):
        assert abs(r["bland_altman"][axis]["bias_deg"]) < 0.02
        assert abs(r["rom_error_deg"][axis]) < 0.05
        assert r["icc"][axis] > 0.9999
    if mode == "cluster":  # the cluster's fixed offset in our hand frame is found too
        X_R = np.array(r["cluster_offset"]["rotation"])
        x_t = np.array(r["cluster_offset"]["translation"])
        # p_cluster = X_R p_hand + x_t, the cluster frame's origin at C1: each cluster marker
        # lands at its distance from C1, C1 itself at the origin.
        for k in range(3):
            assert np.linalg.norm(X_R @ CLUSTER[k] + x_t) == pytest.approx(
                np.linalg.norm(CLUSTER[k] - CLUSTER[0]), abs=5e-5)
    assert r["reaches"]["paired"] >= 1
    pair = r["reaches"]["pairs"][0]
    assert pair["peak_speed_m_s"][0] == pytest.approx(pair["peak_speed_m_s"][1], rel=0.01)


def test_angle_statistics_see_a_planted_bias(scene, tmp_path):
    run, ref, _ = scene
    biased = tmp_path / "biased"
    biased.mkdir()
    cols = read_poses(run / "poses.csv")
    text = (run / "poses.csv").read_text().splitlines()
    header = text[0].split(",")
    j = header.index("flexion_deg")
    rows = [line.split(",") for line in text[1:]]
    for row, value in zip(rows, cols["flexion_deg"], strict=True):
        row[j] = repr(float(value) + 2.5)  # our flexion reads 2.5 deg high: a calibration bias
    (biased / "poses.csv").write_text("\n".join([text[0], *map(",".join, rows)]) + "\n")
    (biased / "summary.json").write_text((run / "summary.json").read_text())
    r = compare(biased, ref, markers=MAP).result
    ba = r["bland_altman"]["flexion"]
    assert ba["bias_deg"] == pytest.approx(2.5, abs=0.02)
    assert ba["loa_high_deg"] - ba["loa_low_deg"] < 0.1
    assert r["rom_error_deg"]["flexion"] == pytest.approx(0.0, abs=0.05)
    assert r["icc"]["flexion"] < r["icc"]["deviation"]  # absolute agreement sees the bias


def test_noisy_tracking_error_is_inside_the_reported_uncertainty(tmp_path):
    """Tracker-like noise (0.5 mm, 0.4 deg, correlated over frames) on our poses and 0.1 mm
    marker noise on the reference: the planted values lie within 3 reported sigma."""
    motion, (R_c0, t_c0) = scenario_motion("mix")
    traj = sample(motion, timestamps(int(motion.duration * 30) + 1, 30.0), R_c0, t_c0)
    rng = np.random.default_rng(5)

    def smooth_noise(n, sd):
        x = rng.normal(0, 1, (n + 4, 3))
        x = (x[:-4] + x[1:-3] + x[2:-2] + x[3:-1] + x[4:]) / np.sqrt(5)
        return x * sd

    def noisy(tr: Trajectory) -> Trajectory:
        n = len(tr.t)
        dR = Rotation.from_rotvec(smooth_noise(n, np.radians(0.4))).as_matrix()
        return Trajectory(tr.t, tr.R_ch @ dR, tr.t_ch + smooth_noise(n, 5e-4), tr.R_rel, tr.p_rel,
                          tr.v, tr.w, tr.angles)

    layout = HandLayout.default()
    run = _run(tmp_path / "run", traj, layout, noisy)
    ref = _reference(tmp_path / "ref.trc", motion, R_c0, t_c0, layout, traj.t[-1], 0.1)
    r = compare(run, ref, markers=MAP).result
    sig = r["registration"]["sigma"]
    assert abs(r["time_offset_s"] - OFFSET) < 3 * r["time_offset_sigma_s"] + 1e-4
    assert abs(r["clock_ratio"] - RATIO) < 3 * r["clock_ratio_sigma"] + 1e-6
    ang, mm = _transform_errors(r)
    assert ang < 3 * sig["rotation_deg"] + 0.005 and mm < 3 * sig["translation_at_hand_mm"] + 0.02
    assert r["pos_rmse_mm"] == pytest.approx(np.sqrt(3) * 0.5, rel=0.15)


def test_a_pose_dependent_error_widens_the_uncertainty_by_the_jackknife(tmp_path, monkeypatch):
    """Our orientation off by 2 % of the hand's turn from neutral (a tilt that grows with the
    angle, as a tracker's does): the fit moves with the part of the movement it sees, which the
    Gauss-Newton covariance of the residuals cannot know. The stated sigma is the larger of
    that and the delete-a-block jackknife's: several times the former here, and the planted
    transform lies within 3 of it."""
    from wristtrack.analysis.compare import register
    from wristtrack.geometry import so3_log

    motion, (R_c0, t_c0) = scenario_motion("mix")
    traj = sample(motion, timestamps(int(motion.duration * 30) + 1, 30.0), R_c0, t_c0)
    rng = np.random.default_rng(5)

    def posed(tr: Trajectory) -> Trajectory:
        turn = 0.02 * so3_log(tr.R_rel) + rng.normal(0, np.radians(0.05), (len(tr.t), 3))
        return Trajectory(tr.t, tr.R_ch @ Rotation.from_rotvec(turn).as_matrix(),
                          tr.t_ch + rng.normal(0, 2e-4, tr.t_ch.shape), tr.R_rel, tr.p_rel,
                          tr.v, tr.w, tr.angles)

    layout = HandLayout.default()
    run = _run(tmp_path / "run", traj, layout, posed)
    ref = _reference(tmp_path / "ref.trc", motion, R_c0, t_c0, layout, traj.t[-1], 0.1)
    both = compare(run, ref, markers=MAP).result
    assert both["registration"]["sigma"]["jackknife_blocks"] == register.JACKKNIFE_BLOCKS
    monkeypatch.setattr(register, "JACKKNIFE_BLOCKS", len(traj.t))  # too few frames per block
    alone = compare(run, ref, markers=MAP).result
    assert alone["registration"]["sigma"]["jackknife_blocks"] == 0
    sig, sig_gn = both["registration"]["sigma"], alone["registration"]["sigma"]
    assert sig["rotation_deg"] > 2 * sig_gn["rotation_deg"]
    assert sig["translation_at_hand_mm"] >= sig_gn["translation_at_hand_mm"]
    ang, mm = _transform_errors(both)
    assert ang < 3 * sig["rotation_deg"] and mm < 3 * sig["translation_at_hand_mm"]


def test_cli_writes_the_contract_keys_and_a_self_contained_page(scene, tmp_path, capsys):
    run, ref, _ = scene
    out = tmp_path / "cmp"
    assert main(["compare", str(run), str(ref), "--markers", MAP, "--out", str(out)]) == 0
    assert "time offset" in capsys.readouterr().out
    r = json.loads((out / "comparison.json").read_text())
    for key in ("time_offset_s", "clock_ratio", "frames_compared", "pos_rmse_mm",
                "rot_rmse_deg", "rom_error_deg", "bland_altman", "icc", "registration"):
        assert key in r
    for axis in ("deviation", "flexion", "pronation"):
        assert set(r["bland_altman"][axis]) >= {"bias_deg", "loa_low_deg", "loa_high_deg"}
        assert isinstance(r["icc"][axis], float) and axis in r["rom_error_deg"]
    assert np.array(r["registration"]["rotation"]).shape == (3, 3)
    assert len(r["registration"]["translation"]) == 3
    page = (out / "comparison.html").read_text()
    assert page.count("data:image/png;base64,") == 4
    assert "http://" not in page and "https://" not in page and "<link" not in page
    import base64
    import re

    import cv2

    for data in re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page):
        img = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and img.shape[1] > 500 and img.std() > 5  # a drawn figure


@pytest.mark.parametrize("args,message", [
    (["--cluster", "C1,C2"], "three or more"),
    (["--cluster", "C1,C2,NOPE"], "no marker 'NOPE'"),
    (["--markers", "THUMB=C1"], "'THUMB' is not one of our markers"),
    (["--markers", "MCP2=MCP2"], "fewer than three markers and not WRIST"),
    ([], "--cluster A,B,C .* or --markers"),
    (["--markers", MAP, "--lowpass", "60"], "Nyquist frequency"),
    (["--markers", MAP, "--lowpass", "0"], "argument --lowpass: 0 is not a finite number > 0"),
    (["--markers", MAP, "--max-lag", "-1"], "argument --max-lag: -1 is not a finite number > 0"),
    (["--markers", MAP, "--time-offset", "nan"], "argument --time-offset: nan is not a finite"),
])
def test_bad_mappings_give_one_line_and_exit_2(scene, tmp_path, capsys, args, message):
    run, ref, _ = scene
    try:
        code = main(["compare", str(run), str(ref), "--out", str(tmp_path / "x"), *args])
    except SystemExit as exc:  # argparse's own
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    import re

    assert re.search(message, err)


def test_a_still_reference_cannot_be_aligned(scene, tmp_path):
    run, _, traj = scene
    n = 300
    still = np.tile(np.random.default_rng(0).normal(0, 0.1, (1, 9, 3)), (n, 1, 1))
    still[:, 3:6] = np.linspace(0.1, 0.5, 3)[:, None]  # markers 4-6 in a line
    names = ("C1", "C2", "C3", "L1", "L2", "L3", *MARKER_NAMES[:3])
    write_trc(tmp_path / "still.trc", MarkerTrajectories(
        names, np.arange(n), np.arange(n) / 100.0, still, 100.0, False, "t"), "mm")
    with pytest.raises(InputError, match="shows no movement"):
        compare(run, tmp_path / "still.trc", cluster="C1,C2,C3")
    with pytest.raises(InputError, match="lie in a line"):
        compare(run, tmp_path / "still.trc", cluster="L1,L2,L3")


def test_implausible_results_are_flagged():
    from wristtrack.analysis.compare.comparison import _warnings

    ok = {"clock_ratio": 1.0002, "speed_correlation": 0.9, "frames_registered": 100,
          "frames_compared": 100}
    assert _warnings(ok, 100) == []
    bad = {**ok, "clock_ratio": 0.7, "speed_correlation": 0.2, "frames_registered": 40}
    text = " ".join(_warnings(bad, 300))
    for phrase in ("implausible", "correlate poorly", "only 40 of 100", "only 100 of our 300"):
        assert phrase in text


def test_a_static_trial_compares_with_a_given_time_offset(tmp_path):
    """A still hand gives the speed cross-correlation nothing to hold on to: with the systems'
    known offset (a hardware trigger) the registration and agreement still come out."""
    from wristtrack.sim.motion import neutral_camera_pose, still

    motion = still(3.0, angles_deg=(5.0, -10.0, 3.0), position=(0.01, 0.0, 0.0))
    R_c0, t_c0 = neutral_camera_pose()
    traj = sample(motion, timestamps(90, 30.0), R_c0, t_c0)
    layout = HandLayout.default()
    run = _run(tmp_path / "run", traj, layout)
    ref = _reference(tmp_path / "ref.trc", motion, R_c0, t_c0, layout, traj.t[-1], 0.05)
    with pytest.raises(InputError, match="shows no movement"):
        compare(run, ref, markers=MAP)
    r = compare(run, ref, markers=MAP, time_offset_s=OFFSET).result
    assert r["time_offset_given"] and r["time_offset_s"] == OFFSET
    assert r["clock_ratio"] == 1.0 and r["time_offset_sigma_s"] == 0.0
    ang, mm = _transform_errors(r)
    assert ang < 0.05 and mm < 0.05
    assert r["pos_rmse_mm"] < 0.1
    # our poses are exact: what disagreement there is, is the reference's 0.05 mm of noise
    assert len(r["warnings"]) == 1 and "the reference's own noise" in r["warnings"][0]


def test_reference_gaps_are_left_out_not_bridged(scene, tmp_path):
    """One marker lost for 0.4 s costs nothing (the rigid fit uses the other five); all of
    them lost: our frames inside the gap are not compared (no interpolation across it) and
    the planted values still come out."""
    from wristtrack.io.markers.trc import read_trc

    run, ref, traj = scene
    data = read_trc(ref)
    xyz = data.xyz.copy()
    lost = (data.times > 3.0) & (data.times < 3.4)
    xyz[lost, 3] = np.nan  # our WRIST as the reference labels it
    one = tmp_path / "one.trc"
    write_trc(one, MarkerTrajectories(data.labels, np.arange(len(xyz)), data.times, xyz,
                                      data.rate, False, "t"), "m")
    full = compare(run, ref, markers=MAP).result
    assert compare(run, one, markers=MAP).result["frames_compared"] == full["frames_compared"]
    xyz[lost, 3:] = np.nan  # all six
    gappy = tmp_path / "gappy.trc"
    write_trc(gappy, MarkerTrajectories(data.labels, np.arange(len(xyz)), data.times, xyz,
                                        data.rate, False, "t"), "m")
    r = compare(run, gappy, markers=MAP).result
    ours_in_gap = ((OFFSET + RATIO * traj.t > 3.0) & (OFFSET + RATIO * traj.t < 3.4)).sum()
    assert full["frames_compared"] - r["frames_compared"] >= ours_in_gap
    assert abs(r["time_offset_s"] - OFFSET) < 2e-4 and _transform_errors(r)[1] < 0.05


def test_a_truth_csv_reference_is_the_camera_frame_on_the_same_clock(scene, tmp_path, capsys):
    run, _, traj = scene
    write_truth(tmp_path / "truth.csv", traj)
    r = compare(run, tmp_path / "truth.csv").result
    assert r["reference"]["kind"] == "truth"
    assert abs(r["time_offset_s"]) < 1e-4 and abs(r["clock_ratio"] - 1) < 1e-5
    np.testing.assert_allclose(r["registration"]["rotation"], np.eye(3), atol=1e-6)
    np.testing.assert_allclose(r["registration"]["translation"], 0.0, atol=1e-5)
    assert r["pos_rmse_mm"] < 0.01 and r["frames_compared"] == len(traj.t)
    assert main(["compare", str(run), str(tmp_path / "truth.csv"), "--cluster", "A,B,C",
                 "--out", str(tmp_path / "x")]) == 2
    assert "takes neither --markers nor --cluster" in capsys.readouterr().err


def test_a_low_passed_reference_loses_its_marker_noise_not_the_motion(scene, tmp_path):
    """Exact poses against a reference with 0.1 mm marker noise: the orientation RMSE is the
    reference's own noise, and --lowpass 10 (of 60 Hz, the reference's Nyquist) takes most of it
    away, near the sqrt(10/60) of white noise; on the noise-free reference the filter leaves the
    motion (every axis and a reach, under 2 Hz) as it was."""
    run, clean, traj = scene
    motion, (R_c0, t_c0) = scenario_motion("mix")
    noisy = _reference(tmp_path / "noisy.trc", motion, R_c0, t_c0, HandLayout.default(),
                       traj.t[-1], noise_mm=0.1, seed=3)
    raw = compare(run, noisy, markers=MAP).result
    low = compare(run, noisy, markers=MAP, lowpass_hz=10.0).result
    assert raw["rot_rmse_deg"] > 0.05  # the noise is what there is to see
    assert low["rot_rmse_deg"] < 0.6 * raw["rot_rmse_deg"]
    assert low["reference"]["lowpass_hz"] == 10.0
    assert "low-passed at 10 Hz" in low["reference"]["notes"][-1]
    exact = compare(run, clean, markers=MAP, lowpass_hz=10.0).result
    assert exact["rot_rmse_deg"] < 0.02 and exact["pos_rmse_mm"] < 0.05


def test_a_truth_reference_refuses_a_low_pass(scene, tmp_path, capsys):
    run, _, traj = scene
    write_truth(tmp_path / "truth.csv", traj)
    assert main(["compare", str(run), str(tmp_path / "truth.csv"), "--out", str(tmp_path / "x"),
                 "--lowpass", "10"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--lowpass is for marker files" in err


@pytest.mark.parametrize("kw", [{"markers": MAP}, {"markers": MAP, "lowpass_hz": 10.0},
                                {"cluster": "C1,C2,C3"}], ids=["markers", "low-passed", "cluster"])
def test_an_exact_run_shows_the_reference_noise_the_reference_reports(scene, tmp_path, kw):
    """Exact poses against 0.1 mm of marker noise: every error compare sees is the reference's,
    and the noise it reads off the reference's own fits says as much (net of it, little is
    left), with a warning that the figures are the reference's."""
    run, _, traj = scene
    motion, (R_c0, t_c0) = scenario_motion("mix")
    noisy = _reference(tmp_path / "noisy.trc", motion, R_c0, t_c0, HandLayout.default(),
                       traj.t[-1], noise_mm=0.1, seed=4)
    comparison = compare(run, noisy, **kw)
    r = comparison.result
    noise = r["reference_noise"]
    if "lowpass_hz" not in kw:
        assert noise["marker_mm"] == pytest.approx(0.1, rel=0.05)
    assert noise["rotation_deg"] == pytest.approx(r["rot_rmse_deg"], rel=0.1)
    assert noise["position_mm"] == pytest.approx(r["pos_rmse_mm"], rel=0.1)
    assert r["rot_rmse_net_deg"] < 0.5 * r["rot_rmse_deg"]
    assert any("the reference's own noise" in w for w in r["warnings"])
    json_text = json.loads(comparison_json(comparison))
    assert json_text["rot_rmse_net_deg"] == pytest.approx(r["rot_rmse_net_deg"])
    page = write_comparison_html(tmp_path / "cmp.html", comparison).read_text()
    assert f"orientation {r['rot_rmse_net_deg']:.2f} deg" in page


def test_our_error_net_of_the_reference_noise_is_the_error_planted(tmp_path):
    """Our orientation off by 0.1 deg per axis each frame and the reference's markers by 0.1 mm:
    the RMSE holds both, and net of the reference's noise it is ours."""
    motion, (R_c0, t_c0) = scenario_motion("mix")
    traj = sample(motion, timestamps(int(motion.duration * 30) + 1, 30.0), R_c0, t_c0)
    dR = Rotation.from_rotvec(np.random.default_rng(6).normal(0, np.radians(0.1), (len(traj.t), 3)))
    ours = float(np.degrees(np.sqrt(np.mean(dR.magnitude() ** 2))))

    def noisy(tr: Trajectory) -> Trajectory:
        return Trajectory(tr.t, tr.R_ch @ dR.as_matrix(), tr.t_ch, tr.R_rel, tr.p_rel, tr.v, tr.w,
                          tr.angles)

    layout = HandLayout.default()
    run = _run(tmp_path / "run", traj, layout, noisy)
    ref = _reference(tmp_path / "ref.trc", motion, R_c0, t_c0, layout, traj.t[-1], 0.1, seed=7)
    r = compare(run, ref, markers=MAP).result
    assert r["rot_rmse_deg"] > 1.2 * ours  # the reference's noise is in it
    assert r["rot_rmse_net_deg"] == pytest.approx(ours, rel=0.07)
    assert not any("the reference's own noise" in w for w in r["warnings"])
