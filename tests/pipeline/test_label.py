"""Manual labelling (`wristtrack label`, `track --labels`) on a rendered recording whose layout
is so symmetric that the automatic labelling must refuse it."""

import csv
import io
import json

import numpy as np
import pytest

from wristtrack.cli import main
from wristtrack.detect.detections import Detections
from wristtrack.errors import InputError
from wristtrack.hand import MARKER_NAMES, HandLayout
from wristtrack.io.poses import read_poses
from wristtrack.pipeline.label import MATCH_RADIUS_PX, ManualLabels
from wristtrack.sim.render import render_recording

N_FRAMES = 12


def hexagon_layout() -> HandLayout:
    """Markers on a regular hexagon (WRIST and MCP3 opposite corners, 80 mm apart): every
    rotation by 60 degrees maps the layout onto itself, so no automatic labelling can tell the
    markers apart, in the image or in depth."""
    ang = np.radians([180, 120, 60, 0, -60, -120])
    pts = np.zeros((6, 3))
    pts[:, 0] = 0.04 + 0.04 * np.cos(ang)
    pts[:, 1] = 0.04 * np.sin(ang)
    pts[0], pts[3, 1] = 0.0, 0.0  # exact zeros where rounding leaves 1e-18
    return HandLayout(pts).validate()


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    root = tmp_path_factory.mktemp("label")
    return render_recording(root / "hex", "deviation", seed=3, n_frames=N_FRAMES, duration=3.0,
                            layout=hexagon_layout())


def _truth_pixels(rec, frame):
    with open(rec / "truth_markers.csv", newline="") as fh:
        row = list(csv.DictReader(fh))[frame]
    return np.array([[float(row[f"{n}_u"]), float(row[f"{n}_v"])] for n in MARKER_NAMES])


def _blobs(capsys_out):
    """Blob table the picker printed: {index: (u, v)}."""
    blobs = {}
    for line in capsys_out.splitlines():
        parts = line.split()
        if len(parts) >= 5 and parts[0].endswith(":") and parts[1] == "u":
            blobs[int(parts[0][:-1])] = (float(parts[2]), float(parts[4]))
    return blobs


def _answers_from_truth(rec, frame):
    """The blob numbers a careful user would type: the detector's blob nearest each truth
    marker (the detector is checked against truth_markers.csv to within 1 px elsewhere)."""
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.label import detect_frame

    with open_recording(rec) as recording:
        _, det = detect_frame(recording, frame)
    truth = _truth_pixels(rec, frame)
    d = np.linalg.norm(truth[:, None] - det.uv[None], axis=-1)
    assert d.min(axis=1).max() < 1.5
    return [int(b) for b in d.argmin(axis=1)]


def _label(monkeypatch, capsys, argv, stdin):
    monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    code = main(["label", *argv])
    return code, capsys.readouterr()


def test_automatic_labelling_refuses_and_manual_labels_track_the_recording(rec, tmp_path,
                                                                          monkeypatch, capsys):
    assert main(["track", str(rec), "--out", str(tmp_path / "auto"), "--no-progress",
                 "--no-report"]) == 2
    assert "ambiguous marker labelling" in capsys.readouterr().err

    answers = _answers_from_truth(rec, 0)
    labels_file = tmp_path / "labels.json"
    code, out = _label(monkeypatch, capsys, [str(rec), "--labels", str(labels_file)],
                       "\n".join(map(str, answers)) + "\n")
    assert code == 0, out.err
    assert (tmp_path / "labels_preview.png").is_file()
    saved = json.loads(labels_file.read_text())
    assert saved["frame"] == 0 and set(saved["markers"]) == set(MARKER_NAMES)
    stored = np.array([saved["markers"][n] for n in MARKER_NAMES])
    assert np.max(np.linalg.norm(stored - _truth_pixels(rec, 0), axis=1)) < 1.5

    assert main(["label", str(rec), "--labels", str(labels_file), "--check"]) == 0
    assert "WRIST = blob" in capsys.readouterr().out

    run = tmp_path / "manual"
    assert main(["track", str(rec), "--out", str(run), "--labels", str(labels_file),
                 "--no-progress", "--no-report"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(run), "--truth", str(rec / "truth.csv")]) == 0
    result = json.loads((run / "evaluation.json").read_text())
    assert result["coverage"] == 1.0
    assert result["position_rmse_mm"] < 3.0 and result["orientation_rmse_deg"] < 2.0


def test_the_picker_reasks_on_bad_answers(rec, tmp_path, monkeypatch, capsys):
    answers = _answers_from_truth(rec, 0)
    script = ["", "seven", "6", "-1", str(answers[0]), str(answers[0])] + list(map(str,
                                                                                   answers[1:]))
    code, out = _label(monkeypatch, capsys, [str(rec), "--labels", str(tmp_path / "l.json")],
                       "\n".join(script) + "\n")
    assert code == 0, out.err
    assert "'seven' is not a blob number" in out.out
    assert "there is no blob 6" in out.out and "there is no blob -1" in out.out
    assert f"blob {answers[0]} is already WRIST" in out.out
    labelled = ManualLabels.load(tmp_path / "l.json")
    np.testing.assert_allclose(labelled.markers, _truth_pixels(rec, 0), atol=1.5)


def test_labels_that_do_not_fit_the_hand_are_asked_again(rec, tmp_path, monkeypatch, capsys):
    answers = _answers_from_truth(rec, 0)
    # WRIST and CMC1 swapped: no rigid pose of the hexagon maps onto that order.
    wrong = [answers[1], answers[0], *answers[2:]]
    script = "\n".join(map(str, wrong + answers)) + "\n"
    code, out = _label(monkeypatch, capsys, [str(rec), "--labels", str(tmp_path / "l.json")],
                       script)
    assert code == 0, out.err
    assert "do not fit the hand" in out.out
    np.testing.assert_allclose(ManualLabels.load(tmp_path / "l.json").markers,
                               _truth_pixels(rec, 0), atol=1.5)


def test_quitting_writes_nothing(rec, tmp_path, monkeypatch, capsys):
    for stdin in ("0\nq\n", "0\n1\n"):  # 'q', and input ending early
        code, out = _label(monkeypatch, capsys, [str(rec), "--labels", str(tmp_path / "l.json")],
                           stdin)
        assert code == 2 and out.err.count("\n") == 1 and "no labels written" in out.err
        assert not (tmp_path / "l.json").exists()


def test_labels_of_a_later_frame_initialise_there(rec, tmp_path, monkeypatch, capsys):
    answers = _answers_from_truth(rec, 4)
    labels_file = tmp_path / "labels4.json"
    code, out = _label(monkeypatch, capsys,
                       [str(rec), "--frame", "4", "--labels", str(labels_file)],
                       "\n".join(map(str, answers)) + "\n")
    assert code == 0, out.err
    assert ManualLabels.load(labels_file).frame == 4
    run = tmp_path / "run"
    assert main(["track", str(rec), "--out", str(run), "--labels", str(labels_file),
                 "--no-progress", "--no-report"]) == 0
    status = read_poses(run / "poses.csv")["status"]
    assert list(status[:4]) == ["initialising"] * 4  # the automatic labelling still refuses
    assert all(s in ("tracking", "coasting") for s in status[4:])
    assert main(["label", str(rec), "--frame", "99", "--labels", str(tmp_path / "x.json")]) == 2
    assert "no frame 99" in capsys.readouterr().err


def test_match_names_blobs_by_pixel_position_and_ignores_clutter():
    markers = np.array([[100, 200], [80, 180], [90, 150], [100, 140], [110, 150], [120, 175.0]])
    manual = ManualLabels(0, 0.0, markers, markers)
    order = [4, 0, 5, 2, 1, 3]  # blob b is marker order[b]; blob 6 is clutter
    uv = np.vstack([markers[order] + 0.7, [[300.0, 300.0]]])
    labels = manual.match(Detections(0.0, uv))
    assert labels.tolist() == [*order, -1]
    far = uv.copy()
    far[1] += MATCH_RADIUS_PX + 1  # the blob of marker 0 (WRIST) moved away
    with pytest.raises(InputError, match="marker WRIST at .* matches no blob"):
        manual.match(Detections(0.0, far))
    both = ManualLabels(0, 0.0, np.vstack([markers[:5], markers[4] + 1.0]), markers)
    with pytest.raises(InputError, match="markers MCP4 and MCP5 match the same blob"):
        both.match(Detections(0.0, uv))


def _write(path, data):
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def test_bad_labels_files_are_one_line_errors(rec, tmp_path, capsys):
    good = {"frame": 0, "timestamp": 0.0, "markers": {n: [300.0 + 5 * k, 250.0] for k, n in
                                                      enumerate(MARKER_NAMES)}}
    cases = {
        "missing.json": (None, "not found"),
        "syntax.json": ('{"frame": 0, "markers": {', "not valid JSON"),
        "list.json": ([1, 2], "expected"),
        "names.json": ({**good, "markers": {**{n: [1, 2] for n in MARKER_NAMES[1:]},
                                            "wrist": [1, 2]}}, "unknown marker name(s) 'wrist'"),
        "pixel.json": ({**good, "markers": {**good["markers"], "MCP3": [1, "a"]}},
                       "marker MCP3 must be a pixel position"),
        "frame.json": ({**good, "frame": -2}, "frame must be a frame index"),
        "nomatch.json": (good, "matches no blob"),
    }
    for name, (data, message) in cases.items():
        path = tmp_path / name if data is None else _write(tmp_path / name, data)
        for argv in (["label", str(rec), "--labels", str(path), "--check"],
                     ["track", str(rec), "--out", str(tmp_path / "run"), "--labels", str(path),
                      "--no-progress", "--no-report"]):
            assert main(argv) == 2, (name, argv[0])
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and message in err and "Traceback" not in err, (name, err)


def test_labels_in_the_wrong_order_stop_the_run_with_one_line(rec, tmp_path, capsys):
    truth = _truth_pixels(rec, 0)
    swapped = truth[[1, 0, 2, 3, 4, 5]]  # WRIST and CMC1 exchanged: every blob still matches
    path = tmp_path / "swapped.json"
    ManualLabels(0, 0.0, swapped, truth).save(path)
    assert main(["label", str(rec), "--labels", str(path), "--check"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "fits the markers badly" in err
    assert main(["track", str(rec), "--out", str(tmp_path / "run"), "--labels", str(path),
                 "--no-progress", "--no-report"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "manual labels of frame 0 do not initialise" in err
