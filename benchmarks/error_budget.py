"""Where the tracker's error comes from: the same recordings tracked again with one source of
error taken away at a time.

Every-effect recordings (``benchmarks.robustness`` conditions with hand.json, both hands): the
default tracker on the detections as they are, then with the blobs that are the markers (each
marker's nearest blob within MATCH_PX or the marker's image diameter of its true image position;
a blob two or three overlapping markers share stands for their mean, as the tracker takes it)
given
- their marker's true depth ("depth exact": the layout's marker at the true pose, so the MCP
  markers' skin slide is left out of it), or the true depth plus white noise of the filter's own
  depth model ("depth drawn from the model": Nguyen et al.'s sigma at the angle the marker is
  seen at, ``MeasurementNoise``);
- their marker's true image position ("pixels exact"), everywhere or only where the back of the
  hand turns away from the camera (cosine between its normal and the line of sight below
  OBLIQUE_COS: the extremes of pronation and extension, where a range of motion is decided);
- both.
True depths are the colour frame's moment: their rows track with no depth delay stated, however
late the rendered depth was (``depth_lag``); the skin between the markers is still read from the
rendered depth map, as late as it was (with the delay stated instead, the rows came out within
0.001 deg). The default tracker without the markers' depth is the last row. What a row gains
over the first is what that source costs.

Sharp pixels, structured-light depth: on structured-light depth alone the default
tracker's orientation error is about twice the clean recording's, where OpenCV's per-frame PnP,
which reads no depth, stays at the clean figure. The clean and structured-light recordings are
tracked on their detections and on detections drawn from the filter's noise model at the same
poses (blobs at the true image positions plus MODEL_PIXEL_SIGMA of white noise, the sharp blobs'
scatter, tracking/pixel_noise.py; true depths plus Nguyen et al.'s sigma), by the default
tracker, without the markers' depth, by OpenCV's per-frame PnP, and by the default tracker with
its pixel noise fixed at MODEL_PIXEL_SIGMA (not learned) and no skin slide or misregistration
modelled (none is rendered), with and without depth. A filter whose noise model is right gains
from depth on such data.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.accuracy import ACCURACY_ROWS, DEFAULT, Row, online, recorded_detections, score
from benchmarks.robustness import _truth_markers, render_condition
from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.hand import marker_image_diameter
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.tracker import Tracker, TrackerConfig

BUDGET_CONDITIONS = ("all (preset real)", "all, left hand")
FUSION_CONDITIONS = ("clean", "structured_light")
MATCH_PX = 3.0  # a blob this near a marker's true image position is that marker's (or within
# the marker's image diameter: a blob that overlapping markers share sits at their mean, which
# for three knuckles lined up is most of a diameter from the outer two. Within the radius only,
# the outer knuckle was left out, the blob made the mean of two where the tracker takes the
# mean of three, and "exact" pixels lost the track at the extremes of the movement.)
VISIBLE = 0.5  # a marker half seen or more gets a model-drawn blob
OBLIQUE_COS = 0.7
_DEPTH_MODEL = MeasurementNoise()  # the default filter's depth sigma
MODEL_PIXEL_SIGMA = 0.015  # px: sharp rendered blobs against the truth (tracking/pixel_noise.py)

AS_DETECTED = "as detected"
OBLIQUE_EXACT = f"pixels exact where the hand turns away (cos < {OBLIQUE_COS})"
BUDGET_DATA = (AS_DETECTED, "depth exact", "depth drawn from the model", "pixels exact",
               OBLIQUE_EXACT, "pixels and depth exact")
NO_DEPTH = "default, no marker depth"
TOLD = "default, pixel noise fixed"
_TOLD_CONFIG = TrackerConfig(
    adapt_pixel=False, adapt_slide=False,
    measurement=MeasurementNoise(pixel_sigma=MODEL_PIXEL_SIGMA, skin_slide=(0.0, 0.0, 0.0),
                                 registration_px=0.0))
TRACKERS: dict[str, Row] = {
    "default": ACCURACY_ROWS[DEFAULT],
    NO_DEPTH: Row(online(lambda c, lay: Tracker(c, lay, TrackerConfig(use_depth=False)))),
    "OpenCV per-frame PnP": ACCURACY_ROWS["OpenCV per-frame (IPPE PnP)"],
    TOLD: Row(online(lambda c, lay: Tracker(c, lay, _TOLD_CONFIG))),
    f"{TOLD}, no marker depth": Row(online(
        lambda c, lay: Tracker(c, lay, replace(_TOLD_CONFIG, use_depth=False)))),
}


def _markers_at(layout, truth, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The markers' true camera-frame centres (6, 3) in frame ``k`` and the cosine between the
    back of the hand's normal and each one's line of sight (6,)."""
    points = layout.points @ truth.R_ch[k].T + truth.t_ch[k]
    facing = -(points @ truth.R_ch[k][:, 2]) / np.linalg.norm(points, axis=1)
    return points, facing


def corrected(detections: list[Detections], truth, layout, uv: np.ndarray, data: str,
              rng: np.random.Generator, fx: float) -> list[Detections]:
    """``detections`` with one source of error taken away (``data``, one of BUDGET_DATA) from
    the blobs that are markers (:func:`_blob_markers`; ``uv`` (N, 6, 2) the markers' true image
    positions, ``fx`` the camera's focal length in px)."""
    if data == AS_DETECTED:
        return detections
    out = []
    for k, det in enumerate(detections):
        if det.count == 0:
            out.append(det)
            continue
        points, facing = _markers_at(layout, truth, k)
        blob_uv = det.uv.copy()
        depth = None if det.depth is None else det.depth.copy()
        reach = np.maximum(MATCH_PX, marker_image_diameter(fx, points[:, 2]))
        for b, markers in _blob_markers(det.uv, uv[k], reach).items():
            # a blob two markers share (their discs overlap) is their mean, as the tracker
            # takes it (tracking/merged.py)
            if data == OBLIQUE_EXACT:
                if facing[markers].min() < OBLIQUE_COS:
                    blob_uv[b] = uv[k, markers].mean(axis=0)
            elif data.startswith("pixels"):
                blob_uv[b] = uv[k, markers].mean(axis=0)
            if depth is not None and np.isfinite(depth[b]):
                z = points[markers, 2].mean()
                if data in ("depth exact", "pixels and depth exact"):
                    depth[b] = z
                elif data == "depth drawn from the model":
                    sigma = _DEPTH_MODEL.depth_sigma(z, facing[markers].mean())
                    depth[b] = z + sigma * rng.standard_normal()
        out.append(replace(det, uv=blob_uv, depth=depth))
    return out


def _blob_markers(blobs: np.ndarray, true_uv: np.ndarray,
                  reach: np.ndarray) -> dict[int, list[int]]:
    """The markers each blob is: every marker's nearest blob within its ``reach`` (6,) px of its
    true image position (``true_uv`` (6, 2)), grouped by blob."""
    out: dict[int, list[int]] = {}
    for j, p in enumerate(true_uv):
        dist = np.linalg.norm(blobs - p, axis=1)
        b = int(np.argmin(dist))
        if dist[b] < reach[j]:
            out.setdefault(b, []).append(j)
    return out


def model_drawn(detections: list[Detections], truth, layout, uv: np.ndarray, vis: np.ndarray,
                rng: np.random.Generator) -> list[Detections]:
    """Detections at the true poses drawn from the filter's noise model: one blob per marker
    seen (``vis`` >= VISIBLE) at its true image position plus white noise of MODEL_PIXEL_SIGMA
    per coordinate, and its true depth plus white noise of the filter's depth sigma (Nguyen et
    al.'s, at the angle the marker is seen at); no clutter, no suspect blob, no depth image (so
    no skin patches)."""
    out = []
    for k, det in enumerate(detections):
        points, facing = _markers_at(layout, truth, k)
        seen = vis[k] >= VISIBLE
        z = points[seen, 2]
        blobs = uv[k, seen] + MODEL_PIXEL_SIGMA * rng.standard_normal((int(seen.sum()), 2))
        sigma = _DEPTH_MODEL.depth_sigma(z, facing[seen])
        depth = z + sigma * rng.standard_normal(z.shape)
        out.append(replace(det, uv=blobs, depth=depth, suspect=None, depth_image=None))
    return out


Result = dict[tuple[str, str, str], dict[str, float]]  # (condition, data, tracker) -> means


def error_budget(cache: Path, seeds: tuple[int, ...], fusion_seeds: tuple[int, ...],
                 n_frames: int | None = None) -> Result:
    """(condition, data, tracker) -> the mean over the seeds of the orientation RMSE ('rot',
    deg) and the worst range-of-motion error ('rom', deg): the budget's rows over ``seeds``,
    the fusion rows over ``fusion_seeds`` (module doc)."""
    scores: dict[tuple[str, str, str], list[dict[str, float]]] = {}
    for condition in BUDGET_CONDITIONS:
        for seed in seeds:
            camera, layout, detections, truth, uv, _ = _recording(cache, condition, seed, n_frames)
            rng = np.random.default_rng(seed)
            for data in BUDGET_DATA:
                dets = corrected(detections, truth, layout, uv, data, rng, camera.fx)
                scores.setdefault((condition, data, "default"), []).append(
                    score(TRACKERS["default"].run(_timed(camera, data), layout, dets), truth))
            scores.setdefault((condition, AS_DETECTED, NO_DEPTH), []).append(
                score(TRACKERS[NO_DEPTH].run(camera, layout, detections), truth))
    for condition in FUSION_CONDITIONS:
        for seed in fusion_seeds:
            camera, layout, detections, truth, uv, vis = _recording(cache, condition, seed,
                                                                    n_frames)
            data = {AS_DETECTED: detections}
            if condition == FUSION_CONDITIONS[-1]:  # the same poses under both: drawn once
                data["drawn from the model"] = model_drawn(detections, truth, layout, uv, vis,
                                                           np.random.default_rng(seed))
            for name, dets in data.items():
                for label, row in TRACKERS.items():
                    key = (condition if name == AS_DETECTED else "(both)", name, label)
                    scores.setdefault(key, []).append(score(row.run(camera, layout, dets), truth))
    return {key: {m: float(np.nanmean([s[m] for s in ss])) for m in ("rot", "rom")}
            for key, ss in scores.items()}


def _timed(camera: Camera, data: str) -> Camera:
    """The camera as the tracker should take it for ``data``: true depths are the colour
    frame's moment, whatever delay the rendered depth had (``depth_lag``)."""
    true_depth = data in ("depth exact", "depth drawn from the model", "pixels and depth exact")
    return replace(camera, depth_delay=0.0) if true_depth else camera


def _recording(cache: Path, condition: str, seed: int, n_frames: int | None):
    folder = render_condition(cache, condition, seed, n_frames)
    camera, layout, detections, truth = recorded_detections(folder)
    uv, vis = _truth_markers(folder)
    return camera, layout, detections, truth, uv, vis


def error_budget_section(result: Result, seeds: tuple[int, ...],
                         fusion_seeds: tuple[int, ...]) -> list[str]:
    """The markdown section of :func:`error_budget`'s result."""
    def table(rows) -> list[str]:
        return ["| condition | data | tracker | rot RMSE (deg) | worst RoM error (deg) |",
                "|---|---|---|---|---|",
                *(f"| {c} | {d} | {t} | {m['rot']:.3f} | {m['rom']:.2f} |"
                  for (c, d, t), m in rows)]

    budget = [(key, m) for key, m in result.items() if key[0] in BUDGET_CONDITIONS]
    fusion = [(key, m) for key, m in result.items() if key[0] not in BUDGET_CONDITIONS]
    lines = [
        "## Where the error comes from",
        "",
        f"Every effect combined (seeds {seeds[0]}-{seeds[-1]}): the default tracker on the "
        "detections as they are, and with one source of error taken away from the blobs that "
        f"are markers (each marker's nearest blob within {MATCH_PX:g} px or its image diameter of "
        "its true image position; a blob two markers share gets their mean; "
        "`benchmarks/error_budget.py`). "
        "'depth exact' leaves the MCP markers' skin slide out of their depth; 'depth drawn from "
        "the model' is the true depth plus white noise of the filter's own depth sigma.",
        "",
        *table(budget),
    ]
    lines += [
        "",
        f"Sharp pixels (seeds {fusion_seeds[0]}-{fusion_seeds[-1]}): the clean and "
        "structured-light recordings, and blobs drawn from the filter's noise model at the same "
        f"poses ('(both)': true image positions + {MODEL_PIXEL_SIGMA} px white noise, true "
        f"depths + the model's sigma). '{TOLD}': pixel sigma {MODEL_PIXEL_SIGMA} px (not "
        "learned), no skin slide or misregistration modelled (none is rendered).",
        "",
        *table(fusion),
    ]
    lines += ["", *_budget_findings(result), *_fusion_findings(result), ""]
    return lines


def _budget_findings(result: Result) -> list[str]:
    """One line per budget condition: what the pixels and the depth cost its worst
    range-of-motion error."""
    out = []
    for c in BUDGET_CONDITIONS:
        base = result.get((c, AS_DETECTED, "default"))
        if base is None:
            continue
        pix = result[(c, "pixels exact", "default")]
        obl = result[(c, OBLIQUE_EXACT, "default")]
        dep = result[(c, "depth exact", "default")]
        out.append(
            f"- {c}: worst RoM {base['rom']:.2f} deg; exact pixels {pix['rom']:.2f} (exact "
            f"only where the hand turns away {obl['rom']:.2f}), exact depth {dep['rom']:.2f}.")
    return out


def _fusion_findings(result: Result) -> list[str]:
    """What the markers' depth is worth to the default tracker and to one with its pixel noise
    fixed, on structured light alone and on blobs drawn from the model."""
    out = []
    for c, data in ((FUSION_CONDITIONS[-1], AS_DETECTED), ("(both)", "drawn from the model")):
        rows = [result.get((c, data, t)) for t in
                ("default", NO_DEPTH, TOLD, f"{TOLD}, no marker depth")]
        if all(m is not None for m in rows):
            d, dn, t, tn = rows
            out.append(
                f"- {c}, {data}: the markers' depth takes the default tracker {dn['rot']:.3f} -> "
                f"{d['rot']:.3f} deg, the one with its pixel noise fixed {tn['rot']:.3f} -> "
                f"{t['rot']:.3f}.")
    return out


def summary_lines(result: Result) -> list[str]:
    """The budget's lines for the document's summary: what exact pixels and exact depth do to
    each every-effect condition's worst range-of-motion error."""
    return [line.replace("- ", "- Error budget, ", 1) for line in _budget_findings(result)]
