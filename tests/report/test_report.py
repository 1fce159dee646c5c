"""report.html + figures/ (report.html, report.figures) and the overlay video (overlay)."""

from __future__ import annotations

import base64
import html
import json
import math
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import pytest

from wristtrack.analysis.summary import SummaryAccumulator
from wristtrack.camera import Camera
from wristtrack.cli import main
from wristtrack.detect.detections import Detections
from wristtrack.errors import InputError
from wristtrack.geometry import matrix_from_quat
from wristtrack.io.atomic import write_json_atomic
from wristtrack.io.open import open_recording
from wristtrack.io.poses import PosesWriter, read_poses
from wristtrack.pipeline.track import track_recording
from wristtrack.report import figures as rf
from wristtrack.report.html import FIGURES, REACH_COLUMNS, build_figures, write_report
from wristtrack.report.overlay import OverlayWriter
from wristtrack.sim.render import render_recording
from wristtrack.tracking.tracker import FrameResult, Status

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def recording(rendered):
    return rendered("reach", seed=0, n_frames=40)


@pytest.fixture(scope="module")
def run(recording, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "run"
    with open_recording(recording) as rec:
        track_recording(rec, out, progress=False)
    report = write_report(out)
    return out, report


class _Cells(HTMLParser):
    """Text of every element with an id, <img> sources, <section> ids and <body> attributes."""

    def __init__(self) -> None:
        super().__init__()
        self.text: dict[str, str] = {}
        self.images: list[str] = []
        self.sections: list[str] = []
        self.body: dict[str, str] = {}
        self._open: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        if tag in ("section", "header") and "id" in attrs:
            self.sections.append(attrs["id"])
        if tag == "body":
            self.body = attrs
        if tag == "td" and "id" in attrs:
            self._open.append(attrs["id"])
            self.text[attrs["id"]] = ""

    def handle_endtag(self, tag):
        if tag == "td" and self._open:
            self._open.pop()

    def handle_data(self, data):
        if self._open:
            self.text[self._open[-1]] += data


def _parse(html_text: str) -> _Cells:
    cells = _Cells()
    cells.feed(html_text)
    return cells


def _close(text: str, value, scale: float = 1.0) -> None:
    """A table cell shows ``value`` * scale, rounded to the digits the cell shows."""
    if value is None:
        assert text.strip() == "\u2013", text
        return
    digits = len(text.split(".")[1]) if "." in text else 0
    assert abs(float(text) - value * scale) <= 0.5 * 10.0**-digits + 1e-9, (text, value)


# ------------------------------------------------------------------------- report content


def test_report_has_every_section_and_the_run_metadata(run):
    out, report = run
    assert report == out / "report.html"
    text = report.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    cells = _parse(text)
    assert cells.sections == ["header", "summary", "reaches"] + [f"fig-{n}" for n, _ in FIGURES]
    for value in (summary["source"], summary["software"]["version"],
                  *summary["conventions"].values()):
        assert str(value) in text.replace("&#x27;", "'"), value
    noise = summary["measurement_noise"]  # the noise the tracker learned, in words
    assert (f"blob centres taken at {noise['pixel_sigma_px']:.2f} px (model "
            f"{noise['pixel_sigma_model_px']:.2f} px)") in text
    assert f"skin slide over the knuckles at {noise['skin_slide_sd_factor']:.2f}x" in text
    assert "depth_delay_s" not in summary["camera"]  # the simulator's default: not stated
    assert "Depth timing" in text and "not stated: each depth frame taken as captured" in text
    # Self-contained: no external resources, nothing fetched.
    assert not re.search(r"(src|href)=\"(https?:|//|file:)", text)
    assert "@page" in text and "A4" in text and "@media print" in text
    # The 40-frame reach is too fast for the tracker in places: the gap must be reported.
    poses = read_poses(out / "poses.csv")
    missing = int(np.isnan(poses["tx"]).sum())
    if missing:
        assert f"{missing} of {len(poses['tx'])} frames have no estimate" in text


def test_summary_and_reach_tables_equal_the_run_files(run):
    out, report = run
    summary = json.loads((out / "summary.json").read_text())
    cells = _parse(report.read_text(encoding="utf-8")).text
    for axis, rom in summary["range_of_motion"].items():
        for field in ("min", "max", "range", "start", "end"):
            _close(cells[f"rom-{axis}-{field}"], rom[f"{field}_deg"])
    _close(cells["peak-speed"], summary["peak_speed_m_s"])
    _close(cells["mean-speed"], summary["mean_speed_m_s"])
    _close(cells["path-length"], summary["path_length_m"], 1000.0)
    _close(cells["duration"], summary["duration_s"])
    _close(cells["frames-total"], summary["frames"]["total"])
    _close(cells["frames-tracked"], summary["frames"]["tracked"])
    _close(cells["frames-lost"], summary["frames"]["lost"])
    _close(cells["clutter"], summary["clutter_blobs_seen"])
    # Independent of the summary: the RoM is the extremes of the angle columns of poses.csv.
    poses = read_poses(out / "poses.csv")
    for axis in rf.AXIS_NAMES:
        _close(cells[f"rom-{axis}-max"], float(np.nanmax(poses[f"{axis}_deg"])))
    from wristtrack.analysis.kinematics import analyse

    kin = summary.get("kinematics") or analyse(poses)
    _check_reach_table(cells, kin["reaches"])


def _check_reach_table(cells: dict[str, str], reaches: list[dict]) -> None:
    for n, reach in enumerate(reaches, 1):
        for key, _, _, scale in REACH_COLUMNS:
            _close(cells[f"reach-{n}-{key}"], reach[key], scale)
    assert f"reach-{len(reaches) + 1}-sparc" not in cells


def test_report_of_the_simulated_truth_lists_its_reach(recording, tmp_path):
    # truth.csv has the poses.csv columns: a report of the truth itself, with a bare summary,
    # must show the reach the simulator performed (the tracked 40-frame run may lose part of it).
    from wristtrack.analysis.kinematics import analyse

    shutil.copy(recording / "truth.csv", tmp_path / "poses.csv")
    truth = read_poses(tmp_path / "poses.csv")
    kin = analyse(truth)
    (tmp_path / "summary.json").write_text(json.dumps({"range_of_motion": kin["range_of_motion"]}))
    text = write_report(tmp_path).read_text(encoding="utf-8")
    assert len(kin["reaches"]) == 1
    cells = _parse(text).text
    _check_reach_table(cells, kin["reaches"])
    # The reach spans the simulated movement: its peak is the truth's peak speed (to the 2 % a
    # resampled profile may differ by).
    v = np.linalg.norm(np.column_stack([truth[c] for c in ("vx", "vy", "vz")]), axis=1)
    assert float(cells["reach-1-peak_speed_m_s"]) == pytest.approx(v.max(), rel=0.02)
    assert cells["peak-speed"] == "\u2013" and "No wrist estimate" not in text
    # The speed figure draws the speed the reach was measured on: its peak mark is the reach's.
    speed_ax = build_figures(truth, kin)["speed"].axes[0]
    peak = next(line for line in speed_ax.lines if line.get_marker() == "v")
    reach = kin["reaches"][0]
    frame = np.median(np.diff(truth["timestamp"]))
    assert peak.get_xdata()[0] == pytest.approx(reach["onset_s"] + reach["time_to_peak_s"],
                                                abs=1.01 * frame)
    assert peak.get_ydata()[0] == pytest.approx(reach["peak_speed_m_s"], rel=0.01)


def test_every_image_is_an_embedded_png_and_matches_the_figures_folder(run):
    out, report = run
    images = _parse(report.read_text(encoding="utf-8")).images
    assert len(images) == len(FIGURES)
    for src, (name, _) in zip(images, FIGURES, strict=True):
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix)
        data = base64.b64decode(src[len(prefix):], validate=True)
        assert data.startswith(PNG_SIGNATURE)
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and img.shape[1] >= 800 and img.shape[0] >= 300
        assert img.std() > 10  # drawn, not blank
        assert (out / "figures" / f"{name}.png").read_bytes() == data


def test_chromium_loads_every_figure(run, tmp_path, chromium):
    out, report = run
    cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}", "--dump-dom",
           report.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    body = _parse(proc.stdout).body
    assert body.get("data-images-failed") == "0", body
    assert body.get("data-images-loaded") == str(len(FIGURES)), body


def test_report_command_regenerates_and_reports_bad_folders(run, tmp_path, capsys):
    out, _ = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("report.html", "figures"))
    assert main(["report", str(copy)]) == 0
    assert (copy / "report.html").is_file()
    assert sorted(p.name for p in (copy / "figures").iterdir()) == sorted(
        f"{n}.png" for n, _ in FIGURES)
    assert not list(copy.glob("*.tmp")) and not list((copy / "figures").glob("*.tmp"))
    capsys.readouterr()
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad").mkdir()
    shutil.copy(out / "poses.csv", tmp_path / "bad" / "poses.csv")
    (tmp_path / "bad" / "summary.json").write_text("{not json")
    for folder, expect in ((tmp_path / "nowhere", "not found"),
                           (tmp_path / "empty", "has no poses.csv"),
                           (tmp_path / "bad", "is not valid JSON")):
        assert main(["report", str(folder)]) == 2
        err = capsys.readouterr().err
        assert expect in err and err.count("\n") == 1 and "Traceback" not in err
        with pytest.raises(InputError):
            write_report(folder)


def _frame_result(i: int, status: Status, n_clutter: int = 0) -> FrameResult:
    return FrameResult.empty(i, i / 30, status, labels=n_clutter)


def test_run_without_any_estimate_gives_a_report_saying_so(tmp_path):
    # A run where the tracker never initialised, written by the pipeline's own writers.
    acc = SummaryAccumulator()
    with PosesWriter(tmp_path / "poses.csv") as writer:
        for i in range(25):
            result = _frame_result(i, Status.INITIALISING, n_clutter=i % 3)
            writer.write_result(result)
            acc.add(result)
    write_json_atomic(tmp_path / "summary.json", acc.to_dict(source="nowhere.bag"))
    text = write_report(tmp_path).read_text(encoding="utf-8")
    assert "No wrist estimate in this run" in text
    cells = _parse(text)
    assert cells.text["rom-flexion-range"] == "\u2013"
    assert cells.text["frames-total"] == "25" and cells.text["clutter"] == "24"
    assert "No reach was found" in text
    assert len(cells.images) == len(FIGURES)
    for name, _ in FIGURES:
        assert (tmp_path / "figures" / f"{name}.png").read_bytes().startswith(PNG_SIGNATURE)


# ------------------------------------------------------------------- figure functions (pure)


def _texts(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def test_empty_state_of_every_pose_figure():
    t = np.arange(10) / 30
    nan = np.full((10, 3), np.nan)
    for fig in (rf.trajectory_figure(nan), rf.angles_figure(t, nan),
                rf.speed_figure(t, np.full(10, np.nan)),
                rf.orientation_figure(nan, np.full((10, 3, 3), np.nan))):
        assert rf.NO_ESTIMATE in _texts(fig)
        assert not any(len(line.get_xdata()) for ax in fig.axes for line in ax.lines)
        assert rf.figure_png(fig).startswith(PNG_SIGNATURE)


def test_gaps_break_the_lines_and_thinning_keeps_them():
    p = np.column_stack([np.arange(50.0), np.zeros(50), np.zeros(50)])
    p[20:23] = np.nan
    line = rf.trajectory_figure(p).axes[0].lines[0]
    x = np.asarray(line.get_xdata(), dtype=float)
    assert np.isnan(x[20:23]).all() and np.isfinite(x[:20]).all()  # NaN: Matplotlib breaks
    finite = np.ones(100_000, bool)
    finite[54_321] = False  # a one-frame gap that plain striding would step over
    idx = rf.plot_indices(finite, max_points=1000)
    assert len(idx) < 1100 and 54_321 in idx and idx[-1] == 99_999


def test_angles_figure_marks_the_range_of_motion():
    t = np.linspace(0, 2, 201)
    a = np.column_stack([25 * np.sin(np.pi * t), -40 * np.sin(np.pi * t) + 5, 0 * t])
    a[170:180] = np.nan  # a gap
    fig = rf.angles_figure(t, a)
    dev, flex, _ = fig.axes
    # sin(pi t) is +1 at t = 0.5 and -1 at t = 1.5: flexion spans -35 to 45.
    assert dev.get_title(loc="left").startswith("deviation: RoM -25.0 to 25.0 deg (range 50.0")
    assert "RoM -35.0 to 45.0 deg (range 80.0" in flex.get_title(loc="left")
    marks = {line.get_marker(): (line.get_xdata()[0], line.get_ydata()[0])
             for line in dev.lines if line.get_marker() in ("^", "v")}
    assert marks["^"] == pytest.approx((0.5, 25.0))
    assert marks["v"] == pytest.approx((1.5, -25.0))


def test_speed_figure_shades_each_reach_and_marks_its_peak():
    t = np.arange(100) / 50
    s = np.where((t > 0.2) & (t < 0.8), np.sin(np.pi * (t - 0.2) / 0.6), 0.0)
    fig = rf.speed_figure(t, s, reaches=[(10, 40), (60, 70)], peaks=[25])
    ax = fig.axes[0]
    spans = [p.get_x() for p in ax.patches]  # axvspan rectangles start at the onset
    assert spans == pytest.approx([t[10], t[60]])
    widths = [p.get_width() for p in ax.patches]
    assert widths == pytest.approx([t[40] - t[10], t[70] - t[60]])
    peak = next(line for line in ax.lines if line.get_marker() == "v")
    assert peak.get_xdata()[0] == pytest.approx(0.5) and peak.get_ydata()[0] == pytest.approx(1)


def test_orientation_figure_draws_the_hand_axes_of_each_instant():
    # Hand turned 90 degrees about Z: its X axis points along W0's +Y, its Y along -X.
    n = 5
    p = np.column_stack([np.linspace(0, 100, n), np.zeros(n), np.zeros(n)])
    R = np.repeat(np.array([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]]), n, axis=0)
    fig = rf.orientation_figure(p, R, count=n)
    xy = fig.axes[0]
    red = [line for line in xy.lines if line.get_color() == rf.HAND_AXIS_COLOURS[0]]
    green = [line for line in xy.lines if line.get_color() == rf.HAND_AXIS_COLOURS[1]]
    assert len(red) == len(green) == n
    for line in red:
        dx, dy = np.diff(line.get_xdata())[0], np.diff(line.get_ydata())[0]
        assert dx == pytest.approx(0, abs=1e-9) and dy == pytest.approx(15.0)  # 15% of 100 mm
    for line in green:
        assert np.diff(line.get_xdata())[0] == pytest.approx(-15.0)


def test_orientation_instants_spread_over_the_movement_not_the_rest():
    # 200 frames at rest with tracking jitter (0.3 mm, 0.3 deg), then 100 frames moving 200 mm.
    rng = np.random.default_rng(3)
    p = np.zeros((300, 3))
    p[:200] += rng.normal(0, 0.3, (200, 3))
    p[200:, 0] = np.linspace(0, 200, 100)
    small = np.radians(0.3) * rng.normal(size=(300, 3))
    R = np.array([cv2.Rodrigues(w)[0] for w in small])
    finite = np.ones(300, bool)
    finite[250] = False  # a frame without estimate is never picked
    picks = rf.sample_instants(finite, 12, p, R)
    assert 10 <= picks.size <= 12 and picks[0] == 0 and picks[-1] == 299 and 250 not in picks
    assert np.sum(picks < 200) == 1  # the rest, however long, gets only its start
    gaps = np.diff(p[picks[1:], 0])
    assert gaps.min() > 10 and gaps.max() < 35  # about 200 mm / 10 between picks
    # Nothing moves: evenly in time.
    assert rf.sample_instants(np.ones(100, bool), 5, np.zeros((100, 3))).tolist() == [
        0, 25, 50, 74, 99]


def test_quality_figure_colours_each_status_run():
    status = np.array(["initialising"] * 3 + ["tracking"] * 10 + ["coasting"] * 2
                      + ["lost"] * 4 + ["tracking"] * 6)
    n = status.size
    t = np.arange(n) / 30
    fig = rf.quality_figure(t, status, np.full(n, 6), np.zeros(n), np.full(n, 12.0),
                            np.full(n, 12), np.ones(n), np.ones(n))
    bands = fig.axes[0].patches
    assert len(bands) == 5
    expected = ["initialising", "tracking", "coasting", "lost", "tracking"]
    for band, name in zip(bands, expected, strict=True):
        assert np.allclose(band.get_facecolor()[:3],
                           tuple(int(rf.STATUS_COLOURS[name][i:i + 2], 16) / 255
                                 for i in (1, 3, 5)))
    assert len(fig.axes) == 4  # status, counts, NIS, uncertainty
    assert len(rf.quality_figure(t, status, np.full(n, 6), np.zeros(n)).axes) == 2


# --------------------------------------------------------------------------- overlay video


def _frames(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(img)
    cap.release()
    return frames


def _dominant(img: np.ndarray, uv, channel: int, r: int = 1) -> bool:
    """Some pixel within r of uv is clearly of BGR channel ``channel`` (0 B, 1 G, 2 R)."""
    u, v = int(round(uv[0])), int(round(uv[1]))
    patch = img[v - r:v + r + 1, u - r:u + r + 1].reshape(-1, 3).astype(int)
    others = np.delete(patch, channel, axis=1).max(axis=1)
    return bool(((patch[:, channel] > 140) & (patch[:, channel] - others > 70)).any())


def _pinhole(camera: Camera, points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, float)
    return np.column_stack([camera.fx * points[:, 0] / points[:, 2] + camera.cx,
                            camera.fy * points[:, 1] / points[:, 2] + camera.cy])


def test_overlay_writer_draws_blobs_clutter_and_axes(tmp_path):
    camera = Camera(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=640, height=480)
    # Back of the hand towards the camera, turned 40 degrees about the image's vertical so all
    # three axes show: X to the right, Y up, Z to the left.
    a = math.radians(40)
    x_axis, z_axis = np.array([math.cos(a), 0, -math.sin(a)]), np.array([-math.sin(a), 0,
                                                                          -math.cos(a)])
    R = np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])
    t = np.array([0.0, 0.0, 0.5])
    result = FrameResult(frame=0, timestamp=0.0, status=Status.TRACKING, R_ch=R, t_ch=t,
                         R=np.eye(3), p=np.zeros(3), v=np.zeros(3), w=np.zeros(3), cov=None,
                         labels=np.array([3, -1]), n_visible=1, n_clutter=1)
    det = Detections(0.0, np.array([[150.0, 120.0], [500.0, 400.0]]))
    grey = np.full((480, 640, 3), 128, np.uint8)
    with OverlayWriter(tmp_path / "o.mp4", camera, None, fps=10) as ov:
        for _ in range(3):
            ov.add(grey, det, result)
        ov.add(grey, det, None)
    frames = _frames(tmp_path / "o.mp4")
    assert len(frames) == 4
    img = frames[0]
    ends = _pinhole(camera, np.vstack([t, t + 0.6 * 0.05 * R.T]))  # 60% along each axis
    for k, channel in enumerate((2, 1, 0)):  # X red, Y green, Z blue
        assert _dominant(img, ends[k + 1], channel), k
    # Associated blob: yellow ring of radius 9 (left side; the name is written to the right).
    ring = [(150 - 9, 120), (150, 120 + 9), (150, 120 - 9)]
    assert all(img[v, u, 2] > 150 and img[v, u, 1] > 150 and img[v, u, 0] < 110
               for u, v in ring)
    assert _dominant(img, (500, 400), 2)  # the clutter cross, red, on its centre
    assert not _dominant(frames[3], ends[1], 2)  # a skipped frame has no axes
    with pytest.raises(InputError, match="name it .mp4"):
        OverlayWriter(tmp_path / "o.avi", camera)
    (tmp_path / "dir.mp4").mkdir()
    with pytest.raises(InputError, match="cannot open overlay video"):
        OverlayWriter(tmp_path / "dir.mp4", camera)


def test_track_writes_the_overlay_and_the_report_by_default(recording, tmp_path, capsys):
    out, video = tmp_path / "run", tmp_path / "overlay.mp4"
    assert main(["track", str(recording), "--out", str(out), "--no-progress",
                 "--overlay", str(video)]) == 0
    assert (out / "report.html").is_file() and (out / "figures" / "speed.png").is_file()
    poses, truth = read_poses(out / "poses.csv"), read_poses(recording / "truth.csv")
    frames = _frames(video)
    assert len(frames) == len(poses["frame"]) == 40
    camera = Camera.load(recording / "camera.json")
    R_true = matrix_from_quat(np.column_stack([truth[c] for c in ("cam_qw", "cam_qx", "cam_qy",
                                                                  "cam_qz")]))
    t_true = np.column_stack([truth[c] for c in ("cam_tx", "cam_ty", "cam_tz")])
    t_est = np.column_stack([poses[c] for c in ("cam_tx", "cam_ty", "cam_tz")])
    good = np.flatnonzero((poses["status"] == "tracking") & (poses["n_visible"] == 6)
                          & (np.linalg.norm(t_est - t_true, axis=1) < 0.003))
    assert good.size >= 10
    markers = np.genfromtxt(recording / "truth_markers.csv", delimiter=",", names=True)
    for i in good[:: max(1, good.size // 4)]:
        img, R, t = frames[i], R_true[i], t_true[i]
        uv = _pinhole(camera, np.vstack([t, t + 0.6 * 0.05 * R.T]))
        for k, channel in ((0, 2), (1, 1)):  # X red, Y green (Z points at the camera here)
            assert _dominant(img, uv[k + 1], channel, r=2), (i, k)
        # CMC1's blob is circled in yellow: its left side, 9 px from the true centre.
        u, v = markers["CMC1_u"][i], markers["CMC1_v"][i]
        yellow = [img[int(round(v)) + dv, int(round(u - 9)) + du] for dv in (-1, 0, 1)
                  for du in (-1, 0, 1)]
        assert any(p[2] > 150 and p[1] > 150 and p[0] < 120 for p in yellow), i
    capsys.readouterr()


def test_track_no_report_skips_it(tmp_path, capsys):
    rec = render_recording(tmp_path / "rec", "deviation", seed=1, n_frames=3)
    assert main(["track", str(rec), "--out", str(tmp_path / "run"), "--no-progress",
                 "--no-report"]) == 0
    assert (tmp_path / "run" / "poses.csv").is_file()
    assert not (tmp_path / "run" / "report.html").exists()
    assert not (tmp_path / "run" / "figures").exists()
    capsys.readouterr()


def test_report_shows_the_runs_warnings_and_its_detector(run, tmp_path):
    """A warning in summary.json (e.g. a colour-only start whose planar flip stayed undecided)
    is a note in the report, never only a key in a file; the tracker line names the detector."""
    out, _ = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("report.html", "figures"))
    summary = json.loads((copy / "summary.json").read_text())
    assert summary["warnings"] == [] and summary["settings"]["detector"] == "default"
    text = "the planar flip was not resolved within 90 frames: the kept pose may be mirrored"
    summary["warnings"] = [text]
    summary["settings"]["detector"] = "paper"
    (copy / "summary.json").write_text(json.dumps(summary))
    html_text = write_report(copy).read_text()
    assert f'<p class="note">{text}</p>' in html_text
    assert "detector paper" in html_text
    assert "Smoothing" not in html_text  # a filtered run


@pytest.mark.parametrize(("noise", "words"), [
    ({"learned_angular_accel": 0.1234, "refit_kept": True},
     "tracked again and smoothed at the angular process noise the recording's rates showed, "
     "0.123 (rad/s²)² s (model 2.50"),
    ({"learned_angular_accel": 0.1234, "refit_kept": False},
     "at the model's angular process noise, 2.50 (rad/s²)² s: tracked again at the 0.123"),
    ({"learned_angular_accel": None, "refit_kept": False},
     "at the model's angular process noise, 2.50 (rad/s²)² s (the recording's rates said too"),
])
def test_report_says_what_the_smoothing_learned(run, tmp_path, noise, words):
    out, _ = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("report.html", "figures"))
    summary = json.loads((copy / "summary.json").read_text())
    summary["smoothing_process_noise"] = {"model_angular_accel": 2.5, **noise}
    (copy / "summary.json").write_text(json.dumps(summary))
    assert words in html.unescape(write_report(copy).read_text())
    assert "was not resolved" not in (out / "report.html").read_text()
