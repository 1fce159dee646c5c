"""The overlay video's frame rate: the recording's own, else from a folder's timestamps."""

from types import SimpleNamespace

import numpy as np

from wristtrack.camera import Camera
from wristtrack.io.folder import RecordingWriter
from wristtrack.io.open import open_recording
from wristtrack.report.overlay import nominal_fps

CAMERA = Camera(fx=100.0, fy=100.0, cx=32.0, cy=24.0, width=64, height=48, depth_scale=0.001)


def test_rate_of_a_recording_folder_is_its_median_frame_interval(tmp_path):
    times = [0.0, 0.04, 0.08, 0.12, 0.20, 0.24]  # 25 Hz with one dropped frame
    with RecordingWriter(tmp_path / "rec", CAMERA) as writer:
        for t in times:
            writer.write(t, np.full((48, 64, 3), 90, np.uint8))
    with open_recording(tmp_path / "rec") as rec:
        np.testing.assert_allclose(rec.timestamps(), times)
        assert abs(nominal_fps(rec) - 25.0) < 1e-9
        (tmp_path / "rec" / "frames.csv").unlink()  # gone since it was opened: the default
        assert nominal_fps(rec, default=12.5) == 12.5


def test_rate_of_a_video_is_its_own_and_otherwise_the_default():
    assert nominal_fps(SimpleNamespace(fps=59.94)) == 59.94
    assert nominal_fps(SimpleNamespace(fps=float("nan"))) == 30.0
    assert nominal_fps(SimpleNamespace(), default=15.0) == 15.0
