"""Realistic synthetic RGB-D recordings with ground truth (``wristtrack simulate``).

Each frame is ray-cast from 3-D geometry with the recording's Camera (so projection,
foreshortening and lens distortion are the tracker's own): a textured table, a skin-coloured
forearm (a tapered round cone), a palm (a convex solid around the marker layout, in the hand
frame) with fingers and thumb (chains of round cones), and the six 12 mm blue markers on the
back of the palm, filled as their projected rim polygons at 8x supersampling (exact sub-pixel
coverage). Every surface is analytic, so the z-buffer gives the depth image too.

Realism on top: Lambert shading with a little gloss, the hand's soft shadow on the table,
vignetting, a slight lens blur, motion blur (the frame is the mean of sub-frame renders over
the exposure), slow brightness and white-balance drift, shot and read noise, and a Kinect-like
depth image. The effects of :mod:`wristtrack.sim.realism` (``Scene.effects``) add a real camera
and a real hand: arched layouts, soft tissue, left hands, lens distortion, auto exposure and
white balance, Bayer demosaicing, JPEG or H.264, a 1/30 s shutter, specular markers and
structured-light depth.

Modules: :mod:`~wristtrack.sim.primitives` (ray-cast geometry), :mod:`~wristtrack.sim.hand_model`,
:mod:`~wristtrack.sim.background`, :mod:`~wristtrack.sim.raycast`, :mod:`~wristtrack.sim.renderer`
(the frames), :mod:`~wristtrack.sim.sensor` and :mod:`~wristtrack.sim.depth_sensor` (the
cameras), :mod:`~wristtrack.sim.codec` (H.264); this module is the entry point.
"""

from __future__ import annotations

import csv
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from wristtrack.hand import MARKER_NAMES
from wristtrack.io.folder import RecordingWriter
from wristtrack.io.poses import write_truth
from wristtrack.sim.hand_model import MARKER_RADIUS
from wristtrack.sim.renderer import RenderedFrame, Renderer
from wristtrack.sim.scenes import RENDER_SCENARIOS, Scene, make_scene

__all__ = ["MARKER_RADIUS", "RENDER_SCENARIOS", "RenderedFrame", "render_frames",
           "render_recording"]


def render_frames(scene: Scene, seed: int = 0) -> Iterator[RenderedFrame]:
    """Render the frames of ``scene`` one at a time (deterministic for a given seed)."""
    renderer = Renderer(scene, seed)
    for t in scene.times:
        yield renderer.frame(float(t))


def render_recording(
    out: str | Path, scenario: str | Scene, seed: int = 0, overwrite: bool = False, **options: Any
) -> Path:
    """Render a synthetic RGB-D recording folder with ground truth; returns its path.

    ``scenario`` is one of RENDER_SCENARIOS (see :func:`wristtrack.sim.scenes.make_scene` for
    ``options``: fps, duration, n_frames, camera, layout, exposure, gain_drift, noise, effects,
    hand_side) or a ready Scene. Writes camera.json (with the lens distortion it was rendered
    through), frames.csv, rgb/ and depth/ PNGs, hand.json (the true, possibly 3-D or left-hand
    layout, unless the scenario has none), truth.csv (the poses.csv columns) and
    truth_markers.csv (per frame and marker: rim-centroid pixel and visible fraction, for
    detector tests). PNG encoding runs in a second thread while the next frame renders.
    """
    out = Path(out)
    scene = scenario if isinstance(scenario, Scene) else make_scene(scenario, seed, **options)
    hand = scene.layout if scene.write_hand else None
    header = ["frame", "timestamp"] + [
        f"{name}_{c}" for name in MARKER_NAMES for c in ("u", "v", "visible")
    ]
    with RecordingWriter(out, scene.camera, hand, overwrite=overwrite) as writer, open(
        out / "truth_markers.csv", "w", newline="", encoding="utf-8"
    ) as fh, ThreadPoolExecutor(max_workers=1) as pool:
        rows = csv.writer(fh, lineterminator="\n")
        rows.writerow(header)

        def write(i: int, fr: RenderedFrame) -> None:
            writer.write(fr.timestamp, fr.bgr, fr.depth)
            cells = [str(i), repr(fr.timestamp)]
            for k in range(6):
                cells += [f"{fr.uv[k, 0]:.4f}", f"{fr.uv[k, 1]:.4f}", f"{fr.visible[k]:.3f}"]
            rows.writerow(cells)

        pending: deque[Future] = deque()
        for i, fr in enumerate(render_frames(scene, seed)):
            pending.append(pool.submit(write, i, fr))
            while len(pending) > 2:  # bounded: a few frames in memory at most
                pending.popleft().result()
        while pending:
            pending.popleft().result()
    write_truth(out / "truth.csv", scene.trajectory(), scene.layout.side)
    return out
