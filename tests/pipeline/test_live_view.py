"""The --view page: its JSON against the run's own poses.csv, its JPEG, a clean close, and a real
browser (headless Chromium) showing the overlay and the traces while a replay is tracked."""

import json
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest

from wristtrack.errors import InputError
from wristtrack.io.live.replay import ReplayRecording
from wristtrack.io.poses import read_poses
from wristtrack.pipeline.live.loop import track_live
from wristtrack.pipeline.live.view import LiveView

AXES = ("deviation", "flexion", "pronation")


@pytest.fixture(scope="module")
def reach(rendered):
    return rendered("reach")


def _get(url):
    with urllib.request.urlopen(url, timeout=5) as response:
        return response.read(), response.headers["Content-Type"]


def test_state_and_frame_match_the_run_and_the_server_closes(reach, tmp_path):
    with ReplayRecording(reach, speed=4.0) as source:
        view = LiveView(source.camera, source.hand.points, port=0, source="test")
        try:
            track_live(source, tmp_path / "run", view=view)
            page, kind = _get(view.url)
            assert kind.startswith("text/html") and b"<canvas" in page
            assert b"http" not in page.replace(b"XMLHttpRequest", b"")  # nothing from outside
            state = json.loads(_get(view.url + "state.json?since=0")[0])
            tail = json.loads(_get(view.url + f"state.json?since={state['next'] - 5}")[0])
            jpeg, kind = _get(view.url + "frame.jpg")
        finally:
            view.close()
    poses = read_poses(tmp_path / "run" / "poses.csv")
    done = poses["status"] != "dropped"
    traces = np.array(state["traces"], dtype=float)  # null (no estimate) -> NaN
    assert state["finished"] and state["ended_by"] == "end of stream"
    assert len(traces) == done.sum() == state["next"]
    np.testing.assert_allclose(traces[:, 0], poses["timestamp"][done], atol=1e-9)
    for k, axis in enumerate(AXES):
        angles = poses[f"{axis}_deg"][done]
        np.testing.assert_allclose(traces[:, k + 1], angles, atol=2e-3, equal_nan=True)
        assert state["rom"][axis]["min_deg"] == pytest.approx(np.nanmin(angles), abs=1e-6)
        assert state["rom"][axis]["max_deg"] == pytest.approx(np.nanmax(angles), abs=1e-6)
    assert state["frame"] == int(poses["frame"][done][-1]) and state["status"] == "tracking"
    assert tail["traces"] == state["traces"][-5:]  # a polling page gets only what is new
    assert kind == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (source.camera.height, source.camera.width, 3)
    with pytest.raises(urllib.error.URLError):
        _get(view.url + "state.json")  # closed: nothing listens any more


def test_a_busy_port_is_one_line(reach):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with ReplayRecording(reach) as source, pytest.raises(InputError) as err:
            LiveView(source.camera, port=port)
    assert f"cannot listen on 127.0.0.1:{port}" in str(err.value)
    assert "--port" in str(err.value)


def _colour_pixels(rgb, colour, tol=40):
    return int((np.abs(rgb.astype(int) - colour).max(axis=2) <= tol).sum())


class HoldLastFrame(ReplayRecording):
    """A replay that keeps its last frame until ``ready()`` (at most ``wait`` s): on a loaded
    machine Chromium may take longer to start than the 4 s recording lasts."""

    def __init__(self, folder, ready, wait=120.0):
        super().__init__(folder)
        self._ready, self._wait = ready, wait

    def _frames(self, start=0):
        n = len(self)
        for frame in super()._frames(start):
            if frame.index == n - 1:
                end = time.monotonic() + self._wait
                while not self._ready() and time.monotonic() < end:
                    time.sleep(0.05)
            yield frame


def test_chromium_shows_the_overlay_and_the_traces_while_tracking(reach, tmp_path, chromium):
    shot = tmp_path / "live.png"
    browser: dict = {}
    view = None

    def page_polled():
        return view is not None and view.requests["state"] >= 3

    with HoldLastFrame(reach, page_polled) as source:
        view = LiveView(source.camera, source.hand.points, port=0, source="replay")

        def screenshot():  # while the main thread tracks the replay
            try:
                browser["proc"] = subprocess.run(
                    [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                     "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
                     "--window-size=1300,800", "--virtual-time-budget=1500",
                     f"--screenshot={shot}", view.url],
                    capture_output=True, text=True, timeout=180,
                )
            except subprocess.TimeoutExpired as exc:
                browser["error"] = f"chromium did not finish in {exc.timeout} s"

        thread = threading.Thread(target=screenshot)
        try:
            thread.start()
            track_live(source, tmp_path / "run", view=view)
            polled_during_run = view.requests["state"]
            thread.join(timeout=200)
        finally:
            view.close()
    assert "error" not in browser, browser.get("error")
    assert browser["proc"].returncode == 0, browser["proc"].stderr[-2000:]
    assert view.requests["page"] >= 1 and view.requests["frame"] >= 1
    assert polled_during_run >= 1  # the page was live while the replay was tracked
    rgb = cv2.cvtColor(cv2.imread(str(shot)), cv2.COLOR_BGR2RGB)
    assert rgb.shape[0] >= 700 and rgb.shape[1] >= 1200
    # the overlay: the yellow circles and names of the markers (nothing else on the page is)
    assert _colour_pixels(rgb, (255, 255, 0), tol=60) > 200
    # the traces: flexion and pronation drawn as lines (the legend and the table's text alone
    # are a few dozen pixels of each colour); deviation stays near 0 under the other two here
    for colour in ((31, 119, 180), (44, 160, 44)):
        assert _colour_pixels(rgb, colour) > 250, colour
