"""C3D and OpenSim TRC exports: a rendered recording tracked, exported, and read back with
independent readers (ezc3d, the `c3d` package, trc-data-reader) against the simulator's truth."""

import csv
import json
import shutil
import sys

import numpy as np
import pytest

from wristtrack.analysis.export import marker_positions
from wristtrack.cli import main
from wristtrack.geometry import matrix_from_quat
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.markers.trajectories import frame_rate
from wristtrack.io.poses import read_poses
from wristtrack.sim.render import render_recording

ezc3d = pytest.importorskip("ezc3d")  # the optional extra; installed with wristtrack[test]
trc = pytest.importorskip("trc")


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    """A 40-frame reach (first 1.3 s of a 2.5 s movement, ~130 mm of travel), tracked with both
    exports requested on the command line."""
    root = tmp_path_factory.mktemp("export")
    rec = render_recording(root / "rec", "reach", seed=0, n_frames=40, duration=2.5)
    run = root / "run"
    argv = ["track", str(rec), "--out", str(run), "--no-progress", "--no-report", "--export", "c3d",
            "--export", "trc"]
    assert main(argv) == 0
    return rec, run


def _truth_markers_mm(rec):
    """Markers from truth.csv poses and the recording's own hand.json, in the truth's W0."""
    t = read_poses(rec / "truth.csv")
    R = matrix_from_quat(np.column_stack([t[c] for c in ("qw", "qx", "qy", "qz")]))
    p = np.column_stack([t[c] for c in ("tx", "ty", "tz")])
    return marker_positions(R, p, HandLayout.load(rec / "hand.json").points) * 1000.0, t


def _read_c3d(path):
    c = ezc3d.c3d(str(path))
    xyz = c["data"]["points"][:3].transpose(2, 1, 0)  # (N, K, 3)
    return c, xyz


def _read_trc(path):
    d = trc.TRCData()
    d.load(str(path))
    xyz = np.array([d[m] for m in d["Markers"]], dtype=float).transpose(1, 0, 2)
    return d, xyz


def test_exports_of_a_tracked_recording_match_the_simulated_truth(tracked):
    rec, run = tracked
    truth, t = _truth_markers_mm(rec)
    assert np.ptp(truth[:, 0, 0]) > 50  # the wrist really moves: the comparison means something
    rate = 1.0 / np.median(np.diff(t["timestamp"]))

    c, xyz_c3d = _read_c3d(run / "markers.c3d")
    point = c["parameters"]["POINT"]
    assert list(point["LABELS"]["value"]) == list(MARKER_NAMES)
    assert point["UNITS"]["value"] == ["mm"]
    assert point["RATE"]["value"][0] == pytest.approx(rate, rel=1e-6)
    assert xyz_c3d.shape == truth.shape
    assert np.max(np.linalg.norm(xyz_c3d - truth, axis=2)) < 3.0  # mm

    d, xyz_trc = _read_trc(run / "markers.trc")
    assert d["Markers"] == list(MARKER_NAMES)
    assert d["Units"] == "mm"
    assert d["DataRate"] == pytest.approx(rate, rel=1e-6)
    assert d["CameraRate"] == pytest.approx(rate, rel=1e-6)
    assert d["NumFrames"] == len(truth) and d["NumMarkers"] == 6
    np.testing.assert_allclose(d["Time"], t["timestamp"], atol=1e-12)
    assert d["Frame#"] == list(range(1, len(truth) + 1))
    assert np.max(np.linalg.norm(xyz_trc - truth, axis=2)) < 3.0
    np.testing.assert_allclose(xyz_trc, xyz_c3d, atol=1e-4)  # both formats say the same


def test_marker_positions_rotate_and_translate_the_layout():
    layout = HandLayout.default().points
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90 deg about Z
    R = np.stack([np.eye(3), Rz, np.full((3, 3), np.nan)])
    p = np.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.03], [np.nan] * 3])
    out = marker_positions(R, p, layout)
    np.testing.assert_allclose(out[0], layout)
    mcp3 = layout[MARKER_NAMES.index("MCP3")]  # (L, 0, 0) -> (0.01, 0.02 + L, 0.03)
    np.testing.assert_allclose(out[1, 3], [0.01, 0.02 + mcp3[0], 0.03])
    np.testing.assert_allclose(out[1, 0], [0.01, 0.02, 0.03])  # WRIST is the origin
    assert np.isnan(out[2]).all()


def test_frame_rate_is_one_over_the_median_interval_and_flags_irregular_timing():
    t = np.arange(10) / 25.0
    assert frame_rate(t) == (pytest.approx(25.0), False)
    jitter = t + np.r_[0, 0.003, 0, -0.003, 0, 0, 0, 0, 0, 0]  # 3 ms of 40 ms: 7.5 %, regular
    assert frame_rate(jitter)[1] is False
    dropped = np.delete(t, 4)  # one 80 ms interval
    assert frame_rate(dropped) == (pytest.approx(25.0), True)


def _edit_poses(run, dst, edit):
    """Copy a run folder, passing poses.csv rows (dicts) through ``edit`` (None drops a row)."""
    shutil.copytree(run, dst)
    with open(run / "poses.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        header, rows = reader.fieldnames, list(reader)
    with open(dst / "poses.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, header, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            row = edit(row)
            if row is not None:
                writer.writerow(row)
    for name in ("markers.c3d", "markers.trc"):
        (dst / name).unlink()
    return dst


GAP = range(12, 17)


def _lose(row, frames=GAP):
    if int(row["frame"]) in frames:
        row["status"] = "lost"
        for key in list(row)[3:]:
            if key not in ("n_visible", "n_clutter", "nis_dof"):
                row[key] = "nan"
    return row


@pytest.mark.filterwarnings("ignore:No analog data")
def test_gap_frames_stay_gaps_in_both_formats(tracked, tmp_path, capsys):
    import c3d as c3d_reader  # trc-data-reader's own C3D dependency: a reader independent of ezc3d

    _, run = tracked
    gappy = _edit_poses(run, tmp_path / "gappy", _lose)
    assert main(["export", str(gappy), "--format", "c3d"]) == 0
    assert main(["export", str(gappy), "--format", "trc", "--out", str(tmp_path / "m.trc")]) == 0
    out = capsys.readouterr()
    assert "35 of 40 frames" in out.out and out.err == ""
    gap = np.isin(np.arange(40), GAP)

    c, xyz = _read_c3d(gappy / "markers.c3d")
    assert xyz.shape[0] == 40
    assert np.isnan(xyz[gap]).all() and np.isfinite(xyz[~gap]).all()
    residuals = c["data"]["meta_points"]["residuals"][0].T  # (N, K)
    assert (residuals[gap] == -1).all() and (residuals[~gap] >= 0).all()
    with open(gappy / "markers.c3d", "rb") as fh:
        frames = [pts for _, pts, _ in c3d_reader.Reader(fh).read_frames()]
    raw_residual = np.array([pts[:, 3] for pts in frames])  # (N, K), as stored in the file
    assert (raw_residual[gap] == -1).all() and (raw_residual[~gap] >= 0).all()

    lines = (tmp_path / "m.trc").read_text().splitlines()
    rows = [line.split("\t") for line in lines[6:]]
    assert len(rows) == 40
    for i, cells in enumerate(rows):
        assert len(cells) == 2 + 18
        assert (all(c == "" for c in cells[2:]) if gap[i] else all(c != "" for c in cells[2:]))
    d, xyz_trc = _read_trc(tmp_path / "m.trc")
    assert np.isnan(xyz_trc[gap]).all() and np.isfinite(xyz_trc[~gap]).all()
    np.testing.assert_allclose(xyz_trc[~gap], xyz[~gap], atol=1e-4)


def test_irregular_timing_keeps_the_timestamps_and_warns(tracked, tmp_path, capsys):
    _, run = tracked
    # Frames 10 and 25 dropped, as a camera drops frames: the median interval stays 1/30 s.
    dropped = _edit_poses(run, tmp_path / "dropped", lambda r: None if r["frame"] in ("10", "25")
                          else r)
    assert main(["export", str(dropped), "--format", "trc", "--units", "m"]) == 0
    assert main(["export", str(dropped), "--format", "c3d"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("irregular" in line for line in err)
    times = read_poses(dropped / "poses.csv")["timestamp"]
    d, xyz_m = _read_trc(dropped / "markers.trc")
    assert d["DataRate"] == pytest.approx(30.0, rel=1e-6) and d["Units"] == "m"
    np.testing.assert_allclose(d["Time"], times, atol=1e-12)  # actual times, not resampled
    assert d["Frame#"][9:11] == [10, 12]  # frame numbers keep the hole
    c, xyz_mm = _read_c3d(dropped / "markers.c3d")
    assert c["parameters"]["POINT"]["RATE"]["value"][0] == pytest.approx(30.0, rel=1e-6)
    np.testing.assert_allclose(xyz_m * 1000.0, xyz_mm, atol=1e-3)


def _error_line(capsys, argv):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_export_errors_are_one_line(tracked, tmp_path, capsys, monkeypatch):
    _, run = tracked
    err = _error_line(capsys, ["export", str(tmp_path / "nope"), "--format", "trc"])
    assert "not found" in err

    no_summary = tmp_path / "no_summary"
    no_summary.mkdir()
    shutil.copy(run / "poses.csv", no_summary / "poses.csv")
    assert "no summary.json" in _error_line(capsys, ["export", str(no_summary), "--format", "trc"])

    no_layout = tmp_path / "no_layout"
    shutil.copytree(run, no_layout)
    summary = json.loads((run / "summary.json").read_text())
    (no_layout / "summary.json").write_text(json.dumps({**summary, "hand_layout": None}))
    assert "no hand layout" in _error_line(capsys, ["export", str(no_layout), "--format", "c3d"])

    never = _edit_poses(run, tmp_path / "never", lambda r: _lose(r, range(40)))
    err = _error_line(capsys, ["export", str(never), "--format", "trc"])
    assert "no frame has a pose estimate" in err
    assert not (never / "markers.trc").exists()

    monkeypatch.setitem(sys.modules, "ezc3d", None)  # as if the extra were not installed
    err = _error_line(capsys, ["export", str(run), "--format", "c3d", "--out",
                               str(tmp_path / "x.c3d")])
    assert "pip install 'wristtrack[c3d]'" in err
