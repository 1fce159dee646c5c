"""``--view``: a live page on 127.0.0.1 while ``wristtrack track --live`` runs.

A standard-library HTTP server in its own threads serves one static page (``page.PAGE``,
no external resources: it works offline in any browser), the newest overlay frame as a JPEG
(``/frame.jpg``: blobs, marker names, wrist axes, as in ``--overlay``) and the running numbers
as JSON (``/state.json?since=N``: status, frame rate, latency, drops, range of motion so far and
the angle samples from N on, so a page polling it draws the traces incrementally). The page
polls rather than streaming MJPEG so a browser (and a headless screenshot) never waits on a
response that does not end.

The tracking loop only hands over references (:meth:`LiveView.publish`); drawing and JPEG
encoding happen in the server thread when a browser asks, at the browser's pace, so the view
costs the tracker nothing when no one watches.
"""

from __future__ import annotations

import json
import math
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlparse

import cv2
import numpy as np

from wristtrack.camera import Camera
from wristtrack.errors import InputError
from wristtrack.geometry import wrist_angles
from wristtrack.pipeline.live.page import PAGE
from wristtrack.report.overlay import OverlayWriter

HOST = "127.0.0.1"  # never another interface: the page shows a patient
DEFAULT_PORT = 8765
JPEG_QUALITY = 80
AXES = ("deviation", "flexion", "pronation")


class _Annotator(OverlayWriter):
    """The ``--overlay`` drawing (OverlayWriter.add) into an image kept in memory: it skips
    OverlayWriter's video file and takes the annotated image where the video would."""

    def __init__(self, camera: Camera, layout_points: np.ndarray | None) -> None:
        self.path = Path("live view")
        self.camera = camera
        self.layout_points = None if layout_points is None else np.asarray(layout_points, float)
        self.size = (int(camera.width), int(camera.height))
        self.frames = 0
        self._writer = self  # OverlayWriter.add hands its image to self._writer.write
        self.image: np.ndarray | None = None

    def write(self, image: np.ndarray) -> None:
        self.image = image

    def release(self) -> None:
        pass


class LiveView:
    """The live page's server; a context manager (closing stops the server).

    ``port`` 0 picks a free port; :attr:`url` is the page's address.
    """

    def __init__(self, camera: Camera, layout_points: np.ndarray | None = None,
                 port: int = DEFAULT_PORT, source: str = "") -> None:
        self._annotator = _Annotator(camera, layout_points)
        self._lock = threading.Lock()
        self._draw_lock = threading.Lock()
        self._latest: tuple | None = None  # (bgr, detections, result) of the newest frame
        self._version = 0
        self._jpeg: tuple[int, bytes] | None = None  # (version, encoded)
        self._traces: list[list[float]] = []  # [timestamp, deviation, flexion, pronation]
        self._rom = np.array([[np.inf, -np.inf]] * 3)
        self._state: dict[str, Any] = {"status": "waiting for the first frame", "source": source,
                                       "finished": False}
        self.requests = {"page": 0, "frame": 0, "state": 0}
        self._finished_seen = threading.Event()
        try:
            self._server = ThreadingHTTPServer((HOST, port), _handler(self))
        except OSError as exc:
            raise InputError(
                f"--view cannot listen on {HOST}:{port} ({exc.strerror}); pass --port with a "
                "free port (or --port 0 to pick one)"
            ) from None
        self._server.daemon_threads = True
        self.port = self._server.server_address[1]
        self.url = f"http://{HOST}:{self.port}/"
        self._thread = threading.Thread(target=self._server.serve_forever,
                                        name="wristtrack-view", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ from the tracking loop

    def publish(self, bgr: np.ndarray, detections, result, stats: dict[str, Any]) -> None:
        """The newest processed frame, its detections and estimate, and the loop's numbers."""
        angles = [math.nan] * 3
        if result is not None and result.has_estimate:
            angles = np.degrees(wrist_angles(np.asarray(result.R, float), result.side)).tolist()
        with self._lock:
            self._latest = (bgr, detections, result)
            self._version += 1
            self._traces.append([float(result.timestamp), *angles])
            a = np.asarray(angles)
            seen = np.isfinite(a)
            self._rom[seen, 0] = np.minimum(self._rom[seen, 0], a[seen])
            self._rom[seen, 1] = np.maximum(self._rom[seen, 1], a[seen])
            self._state.update(stats)
            self._state.update(status=str(result.status), frame=int(result.frame),
                               timestamp=float(result.timestamp),
                               markers=int(result.n_visible), clutter=int(result.n_clutter))

    def finish(self, stats: dict[str, Any], ended_by: str) -> None:
        """The run has ended: the page says so (and stops polling)."""
        with self._lock:
            self._state.update(stats)
            self._state.update(finished=True, ended_by=ended_by)

    # ------------------------------------------------------------------ for the HTTP threads

    def state(self, since: int) -> dict[str, Any]:
        with self._lock:
            rom = {axis: None if not math.isfinite(lo) else
                   {"min_deg": lo, "max_deg": hi, "range_deg": hi - lo}
                   for axis, (lo, hi) in zip(AXES, self._rom.tolist(), strict=True)}
            since = min(max(since, 0), len(self._traces))
            data = {**self._state, "version": self._version, "rom": rom,
                    "next": len(self._traces),
                    "traces": [[row[0]] + [None if x != x else round(x, 3) for x in row[1:]]
                               for row in self._traces[since:]]}
        if data["finished"]:
            self._finished_seen.set()
        return data

    def jpeg(self) -> bytes | None:
        with self._lock:
            latest, version, cached = self._latest, self._version, self._jpeg
        if latest is None:
            return None
        if cached is not None and cached[0] == version:
            return cached[1]
        # Its own lock: publish() (the tracking loop) never waits for drawing and encoding.
        with self._draw_lock:
            self._annotator.add(*latest)
            ok, buf = cv2.imencode(".jpg", self._annotator.image,
                                   [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
            data = buf.tobytes() if ok else None
        if data is not None:
            with self._lock:
                self._jpeg = (version, data)
        return data

    # ------------------------------------------------------------------------------ closing

    def close(self, linger: float = 1.0) -> None:
        """Stop serving. A page that has been polling gets up to ``linger`` seconds to fetch
        the final state first, so it shows the run's end rather than a lost connection."""
        if self.requests["state"] and self._state.get("finished"):
            self._finished_seen.wait(linger)
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _handler(view: LiveView) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "wristtrack-live"

        def do_GET(self) -> None:  # noqa: N802 (http.server's name)
            url = urlparse(self.path)
            if url.path in ("/", "/index.html"):
                view.requests["page"] += 1
                self._send(PAGE.encode("utf-8"), "text/html; charset=utf-8")
            elif url.path == "/state.json":
                view.requests["state"] += 1
                try:
                    since = int(parse_qs(url.query).get("since", ["0"])[0])
                except ValueError:
                    since = 0
                body = json.dumps(view.state(since), allow_nan=False).encode("utf-8")
                self._send(body, "application/json")
            elif url.path == "/frame.jpg":
                view.requests["frame"] += 1
                data = view.jpeg()
                if data is None:
                    self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, "no frame yet")
                else:
                    self._send(data, "image/jpeg")
            else:
                self.send_error(HTTPStatus.NOT_FOUND)

        def _send(self, body: bytes, kind: str) -> None:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            try:
                self.wfile.write(body)
            except (BrokenPipeError, ConnectionResetError):
                pass  # the browser went away: nothing to do

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
            pass  # no access log on the terminal the tracker reports to

    return Handler

