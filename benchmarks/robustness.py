"""Robustness table: each simulator realism effect alone, then all of them combined, on rendered
RGB-D recordings, for the default tracker and its peers.

Every condition is the same rendered movement (the ``no_hand`` scenario's mix of all three
wrist axes, with hand.json written unless the condition says otherwise) with the effects of
:mod:`wristtrack.sim.realism` switched on at their realistic strengths. The detector runs once
per recording as ``track`` runs it (:func:`benchmarks.accuracy.recorded_detections`); every
tracker gets the same blobs and is scored by the same code: orientation and position RMSE, the
worst range-of-motion error, coverage (:func:`benchmarks.accuracy.score`) and detection recall:
markers used / markers visible, where a marker counts as used in a frame when a blob within
3 px of its true image position carries its label (a mislabelled blob is not a use), and as
visible when at least half of it can be seen (truth_markers.csv).
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.accuracy import (
    ACCURACY_ROWS,
    DEFAULT,
    LEARNED_SMOOTHED,
    Row,
    recorded_detections,
    score,
)
from wristtrack.geometry import rotation_distance
from wristtrack.hand import MARKER_NAMES
from wristtrack.sim.realism import EFFECTS, PRESET_REAL
from wristtrack.sim.render import render_recording
from wristtrack.sim.scenes import make_scene, mirrored
from wristtrack.tracking.observation import registration_depth_jacobian
from wristtrack.tracking.pixel_noise import WINDOW_S, BlobCorrelation, worst_inflation

BASE_SCENARIO = "no_hand"  # the 'mix' movement, all three axes; hand.json per condition
USED_PX = 3.0

# condition -> make_scene options (effects, hand_side) and whether hand.json is written
CONDITIONS: dict[str, dict[str, Any]] = {
    "clean": {},
    **{e: {"effects": [e]} for e in EFFECTS if e != "left_hand"},
    "left hand": {"hand_side": "left"},
    # Without hand.json the layout is estimated at the first fix: an arched palm, a left hand.
    "nonplanar, no hand.json": {"effects": ["nonplanar"], "write_hand": False},
    "left hand, no hand.json": {"hand_side": "left", "write_hand": False},
    "all (preset real)": {"effects": list(PRESET_REAL)},
    "all, left hand": {"effects": list(PRESET_REAL), "hand_side": "left"},
    "all, no hand.json": {"effects": list(PRESET_REAL), "write_hand": False},
    "all, left hand, no hand.json": {"effects": list(PRESET_REAL), "hand_side": "left",
                                     "write_hand": False},
    # The rows above move both hands through the same rotations in the camera's frame, so each
    # hand makes its own signs of deviation and pronation. A right hand making the left hand's
    # (ulnar deviation with supination) turns its back away from the lamp at the extremes; a
    # left hand making the right hand's turns the thumb side edge-on to the camera there, where
    # the sensor reads the markers on the silhouette in part.
    "all, right hand, mirrored movement": {"effects": list(PRESET_REAL), "mirror_movement": True},
    "all, left hand, mirrored movement": {"effects": list(PRESET_REAL), "hand_side": "left",
                                          "mirror_movement": True},
}

TRACKERS: dict[str, str] = {  # table label -> row of benchmarks.accuracy.ACCURACY_ROWS
    "default": DEFAULT,
    "OpenCV per-frame PnP": "OpenCV per-frame (IPPE PnP)",
    "Stone Soup UKF + PDA": "Stone Soup UKF + PDA",
    "paper": "paper model, paper's rule",
}
# The combined conditions also get the offline smoother's row: the issue's target for the
# smoothed range of motion (<= 0.7 deg).
SMOOTHED = "default, smoothed (offline)"
LEARNED = "default, smoothed at the learned noise (offline)"
COMBINED_EXTRA = {SMOOTHED: "default + smoother (offline)", LEARNED: LEARNED_SMOOTHED}


def render_condition(cache: Path, condition: str, seed: int, n_frames: int | None) -> Path:
    """The recording of one condition, rendered into ``cache`` (re-rendered every time: the
    simulator may have changed since a cached copy)."""
    spec = dict(CONDITIONS[condition])
    write_hand = spec.pop("write_hand", True)
    mirror = spec.pop("mirror_movement", False)
    scene = make_scene(BASE_SCENARIO, seed, **spec)
    if mirror:
        scene = replace(scene, motion=mirrored(scene.motion))
    # A reduced run keeps the natural speed: the first n_frames frames, not the whole movement
    # squeezed into them.
    times = scene.times[:n_frames] if n_frames else scene.times
    scene = replace(scene, write_hand=write_hand, name=condition, times=times)
    slug = "".join(c if c.isalnum() else "_" for c in condition)
    folder = cache / (f"robust-{slug}-{seed}" + (f"-n{n_frames}" if n_frames else ""))
    return render_recording(folder, scene, seed=seed, overwrite=True)


def _truth_markers(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(N,6,2) true marker image positions and (N,6) visible fractions."""
    with open(folder / "truth_markers.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    uv = np.array([[[float(r[f"{n}_u"]), float(r[f"{n}_v"])] for n in MARKER_NAMES]
                   for r in rows])
    vis = np.array([[float(r[f"{n}_visible"]) for n in MARKER_NAMES] for r in rows])
    return uv, vis


def recall(results: list, detections: list, uv: np.ndarray, vis: np.ndarray) -> float:
    """Markers used / visible. A marker is used where a blob with its label lies within
    USED_PX of its truth, or where a blob measured the mean of merged markers among them
    (FrameResult.merged) and lies within USED_PX of the mean of their truths: the filter took
    that blob for all of them (tracking/merged.py). Counted by the label alone, the rendered
    right hands making the left hand's movement, whose knuckles line up at the extremes,
    came out at 97.3-98.5 % (6 seeds) where 98.9-100 % of their markers were used."""
    used = visible = 0
    for k, (res, det) in enumerate(zip(results, detections, strict=True)):
        seen = vis[k] >= 0.5
        visible += int(seen.sum())
        if not res.has_estimate or det.count == 0:
            continue
        for blob, label in enumerate(res.labels):
            if label < 0:
                continue
            markers = np.array(res.merged.get(blob, (label,)))
            if np.linalg.norm(det.uv[blob] - uv[k, markers].mean(axis=0)) < USED_PX:
                used += int(seen[markers].sum())
    return used / visible if visible else float("nan")


def blob_errors(detections: list, uv: np.ndarray, vis: np.ndarray) -> dict[str, float]:
    """The detector's blob centres against the truth, whatever a tracker makes of them: each
    visible marker's nearest blob within USED_PX of it (a blob two overlapping markers share
    counts for both). ``blob_rms``, ``blob_rms_undoubted`` and ``blob_median``: its distance (px)
    over all of them, over those the detector does not doubt (``Detections.suspect``), its
    median; ``blob_doubted``: the share doubted; ``blob_found``: visible markers with a blob."""
    dist, doubted, visible = [], [], 0
    for k, det in enumerate(detections):
        seen = np.flatnonzero(vis[k] >= 0.5)
        visible += seen.size
        if det.count == 0 or seen.size == 0:
            continue
        d = np.linalg.norm(det.uv[None] - uv[k, seen][:, None], axis=2)  # (markers, blobs)
        nearest = d.argmin(axis=1)
        near = d[np.arange(seen.size), nearest] < USED_PX
        dist.extend(d[np.arange(seen.size), nearest][near])
        flags = np.zeros(det.count, bool) if det.suspect is None else det.suspect
        doubted.extend(flags[nearest[near]])
    e, s = np.asarray(dist), np.asarray(doubted, bool)
    return {
        "blob_rms": _rms(e), "blob_rms_undoubted": _rms(e[~s]),
        "blob_median": float(np.median(e)) if e.size else float("nan"),
        "blob_doubted": float(s.mean()) if s.size else float("nan"),
        "blob_found": e.size / visible if visible else float("nan"),
    }


def robustness(
    cache: Path, seeds: tuple[int, ...] = (0,), n_frames: int | None = None,
    conditions: tuple[str, ...] | None = None, trackers: dict[str, str] | None = None,
) -> dict[str, dict[str, dict[str, float]]]:
    """condition -> tracker -> metrics (mean over seeds): rot, pos, rom, cover, recall,
    ``wrong_side`` (frames whose estimate reports the other hand), and the detector's
    :func:`blob_errors` (the same for every tracker)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for condition in conditions or tuple(CONDITIONS):
        per = per_seed(cache, condition, seeds, n_frames, trackers)
        out[condition] = {
            label: {key: _mean([m.get(key, np.nan) for m in ms]) for key in ms[0]}
            for label, ms in per.items()
        }
    return out


def per_seed(
    cache: Path, condition: str, seeds: tuple[int, ...], n_frames: int | None = None,
    trackers: dict[str, str] | None = None,
) -> dict[str, list[dict[str, float]]]:
    """tracker -> each seed's metrics on ``condition`` (a combined condition also gets the
    default tracker's smoothed row)."""
    rows = dict(TRACKERS if trackers is None else trackers)
    if condition.startswith("all") and "default" in rows:
        rows.update(COMBINED_EXTRA)
    per: dict[str, list[dict[str, float]]] = {label: [] for label in rows}
    side = "left" if CONDITIONS[condition].get("hand_side") == "left" else "right"
    for seed in seeds:
        folder = render_condition(cache, condition, seed, n_frames)
        camera, hand, detections, truth = recorded_detections(folder)
        uv, vis = _truth_markers(folder)
        blobs = blob_errors(detections, uv, vis)
        if hand is not None and any(d.depth is not None for d in detections):
            points = np.einsum("nij,kj->nki", truth.R_ch, hand.points) + truth.t_ch[:, None]
            blobs.update(depth_errors(detections, uv, vis, points, truth.R_ch[:, :, 2],
                                      truth.t, camera.fx, camera.fy))
        for label, row_name in rows.items():
            row: Row = ACCURACY_ROWS[row_name]
            results = row.run(camera, hand, detections)
            m = score(results, truth)
            m["recall"] = recall(results, detections, uv, vis)
            m.update(uncertainty_ratios(results, truth))
            est = [r for r in results if r.has_estimate]
            m["wrong_side"] = float(np.mean([r.side != side for r in est])) if est else 0.0
            per[label].append({**m, **blobs})
    return per


def uncertainty_ratios(results: list, truth) -> dict[str, float]:
    """How honest the reported uncertainty is: the RMS orientation error (deg) over the RMS
    rot_sigma_deg, and the RMS position error (mm) over the RMS pos_sigma_mm, over the frames
    with an estimate and a sigma (NaN: none). The sigmas are root-trace 1-sigma values, whose
    squares are the expected squared errors: 1 is honest, below 1 conservative, above 1
    overconfident."""
    R = np.stack([r.R_ch for r in results])
    t = np.stack([r.t_ch for r in results])
    rot_sigma = np.array([r.rot_sigma_deg for r in results], dtype=float)
    pos_sigma = np.array([r.pos_sigma_mm for r in results], dtype=float)
    n = len(results)
    ok = (np.isfinite(R).all(axis=(1, 2)) & np.isfinite(t).all(axis=1)
          & np.isfinite(rot_sigma) & np.isfinite(pos_sigma))
    if not ok.any():
        return {"rot_z": float("nan"), "pos_z": float("nan")}
    rot_err = np.degrees(rotation_distance(R[ok], truth.R_ch[:n][ok]))
    pos_err = 1e3 * np.linalg.norm(t[ok] - truth.t_ch[:n][ok], axis=1)
    return {"rot_z": _rms(rot_err) / _rms(rot_sigma[ok]),
            "pos_z": _rms(pos_err) / _rms(pos_sigma[ok])}


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def _mean(values: list[float]) -> float:
    """Mean over the seeds that have the figure (NaN, quietly, when none has)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


def _f(x: float, fmt: str) -> str:
    return "n/a" if not np.isfinite(x) else format(x, fmt)


def depth_errors(detections: list, uv: np.ndarray, vis: np.ndarray, points: np.ndarray,
                 normals: np.ndarray, times: np.ndarray, fx: float, fy: float
                 ) -> dict[str, float]:
    """The markers' depth as the detector read it against the truth: each visible marker's
    nearest blob within USED_PX (as :func:`blob_errors`) with a depth, against the marker
    centre's true depth (``points`` (N, 6, 3) camera frame; ``normals`` (N, 3) the back of the
    hand's, ``times`` (N,) s). Each marker's mean error over the recording (the blob's depth is
    read on the marker's surface, not at its centre) is taken out. ``depth_rms`` (mm) the rest;
    ``depth_inflation`` the variance of its half-second sums over white noise's
    (``pixel_noise.BlobCorrelation``: 1 for white errors, the frames of a window for constant
    ones); ``depth_offset`` (px) the colour-depth offset s fitted to the errors with the means,
    as the depth off the blob on the hand's tilted surface (dz = G s,
    ``observation.registration_depth_jacobian``), and ``depth_rms_offset`` (mm),
    ``depth_inflation_offset`` what is left of the errors once that is taken out."""
    n = len(detections)
    e = np.full((n, 6), np.nan)
    G = np.zeros((n, 6, 2))
    for k, det in enumerate(detections):
        G[k] = registration_depth_jacobian(points[k], normals[k], 1.0, fx, fy)
        seen = np.flatnonzero(vis[k] >= 0.5)
        if det.count == 0 or det.depth is None or seen.size == 0:
            continue
        d = np.linalg.norm(det.uv[None] - uv[k, seen][:, None], axis=2)
        nearest = d.argmin(axis=1)
        near = d[np.arange(seen.size), nearest] < USED_PX
        e[k, seen[near]] = det.depth[nearest[near]] - points[k, seen[near], 2]
    ok = np.isfinite(e)
    if ok.sum() < 8:
        return {}
    rest = e - np.nansum(e, axis=0) / np.maximum(ok.sum(axis=0), 1)  # each marker's mean out
    marker = np.nonzero(ok)[1]
    A = np.concatenate((G[ok], np.eye(6)[marker]), axis=1)
    fit, *_ = np.linalg.lstsq(A, e[ok], rcond=None)
    after = np.full_like(e, np.nan)
    after[ok] = e[ok] - A @ fit
    frames = int(worst_inflation(float(np.median(np.diff(times)))) or 1) if n > 1 else 1
    return {
        "depth_rms": 1e3 * _rms(rest[ok]), "depth_inflation": _inflation(rest, frames),
        "depth_offset": float(np.linalg.norm(fit[:2])),
        "depth_rms_offset": 1e3 * _rms(after[ok]),
        "depth_inflation_offset": _inflation(after, frames),
    }


def _inflation(errors: np.ndarray, frames: int) -> float:
    """BlobCorrelation's inflation of ``errors`` (N, markers) in windows of ``frames`` frames
    (NaN: too few windows)."""
    correlation = BlobCorrelation()
    for start in range(0, len(errors) - frames + 1, frames):
        correlation.add(errors[start:start + frames], WINDOW_S)
    inflation = correlation.inflation
    return float("nan") if inflation is None else inflation


def robustness_sections(
    cache: Path, seeds: tuple[int, ...] = (0,), n_frames: int | None = None,
    findings: dict | None = None, conditions: tuple[str, ...] | None = None,
    trackers: dict[str, str] | None = None,
) -> list[str]:
    """The markdown section of the robustness table (and ``findings['robustness']``)."""
    acc = robustness(cache, seeds, n_frames, conditions, trackers)
    if findings is not None:
        findings["robustness"] = acc
    lines = [
        "| condition | tracker | rot RMSE (deg) | pos RMSE (mm) | worst RoM error (deg) | "
        "recall | coverage |",
        "|---|---|---|---|---|---|---|",
    ]
    for condition, rows in acc.items():
        for label, m in rows.items():
            lines.append(
                f"| {condition} | {label} | {_f(m['rot'], '.2f')} | {_f(m['pos'], '.1f')} | "
                f"{_f(m['rom'], '.2f')} | {_f(100 * m['recall'], '.1f')}% | "
                f"{_f(100 * m['cover'], '.1f')}% |"
            )
    length = f"its first {n_frames} frames" if n_frames else "all of it"
    return [
        "## Robustness: a real camera and a real hand",
        "",
        f"The rendered `{BASE_SCENARIO}` movement at natural speed ({length}, seeds "
        f"{list(seeds)}) with each "
        "simulator effect alone at its realistic strength (`wristtrack.sim.realism`: numbers "
        "from real devices and the literature), then combined (`simulate --preset real`: "
        "every effect but H.264 and the side of the hand), for both hands and without "
        "hand.json. Both hands go through the same "
        "rotations in the camera's frame, so each makes its own signs of deviation and "
        "pronation; 'mirrored movement' is each hand making the other's: the right hand "
        "ulnar deviation with supination at extension, which turns the back of the hand from "
        "the lamp, the left hand radial deviation with pronation (`sim.scenes.mirrored`). "
        "The detector runs as `track` runs it, and so does the default tracker (its noise "
        "primed over the recording's first 10 s); every tracker gets the same blobs. "
        "Recall: markers used with their right label (blob "
        f"within {USED_PX:g} px of the truth) / markers visible.",
        "",
        *lines,
        "",
        *summary_lines(acc),
        "",
        *uncertainty_table(acc),
        *blob_table(acc),
        *depth_table(acc),
    ]


def uncertainty_table(acc: dict[str, dict[str, dict[str, float]]]) -> list[str]:
    """The default tracker's reported uncertainty against its errors (:func:`uncertainty_ratios`),
    filtered and, for the combined conditions, smoothed."""
    lines = [
        "The uncertainty poses.csv reports (rot_sigma_deg, pos_sigma_mm: root-trace 1 sigma) "
        "against the errors: RMS error / RMS reported sigma, mean over the seeds. 1 is honest, "
        "below 1 conservative (the errors are smaller than reported), above 1 overconfident.",
        "",
        "| condition | orientation, filtered | smoothed | position, filtered | smoothed |",
        "|---|---|---|---|---|",
    ]
    for condition, rows in acc.items():
        m, sm = rows.get("default"), rows.get(SMOOTHED, {})
        if m is None or "rot_z" not in m:
            continue
        cells = [_f(m["rot_z"], ".2f"), _f(sm.get("rot_z", np.nan), ".2f"),
                 _f(m["pos_z"], ".2f"), _f(sm.get("pos_z", np.nan), ".2f")]
        lines.append(f"| {condition} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def blob_table(acc: dict[str, dict[str, dict[str, float]]]) -> list[str]:
    """The detector's blob centres against the truth per condition (:func:`blob_errors`)."""
    return _detector_table(
        acc,
        "The detector's blob centres against the truth (the same blobs for every tracker): each "
        f"visible marker's nearest blob within {USED_PX:g} px, mean over the seeds; doubted: "
        "clipped, split, elongated, on the border, a streak (taken at the model's pixel noise).",
        (("rms (px)", "blob_rms", ".3f"), ("rms, undoubted (px)", "blob_rms_undoubted", ".3f"),
         ("median (px)", "blob_median", ".3f"), ("doubted", "blob_doubted", "%"),
         ("markers with a blob", "blob_found", "%")),
    )


def depth_table(acc: dict[str, dict[str, dict[str, float]]]) -> list[str]:
    """The markers' depth as read against the truth per condition (:func:`depth_errors`)."""
    return _detector_table(
        acc,
        "The markers' depth as the detector read it against the truth (the same for every "
        "tracker; conditions with hand.json: their twins without it are the same recordings): "
        "each marker's mean error taken out, rms per frame; the inflation is the variance of "
        "half-second sums over white noise's (1: white, ~16: constant over the half second), "
        "the errors a filter weighing half a second of frames as independent meets; then the "
        "fixed colour-depth offset fitted to them (the depth read off the blob, on the hand's "
        "tilted surface), and what is left. The truth's marker centres leave out the MCP "
        "markers' skin slide, which shows here as error under soft tissue. Mean over the seeds.",
        (("rms (mm)", "depth_rms", ".2f"), ("inflation", "depth_inflation", ".1f"),
         ("offset fitted (px)", "depth_offset", ".2f"),
         ("rms less the offset (mm)", "depth_rms_offset", ".2f"),
         ("inflation less the offset", "depth_inflation_offset", ".1f")),
    )


def _detector_table(acc: dict[str, dict[str, dict[str, float]]], intro: str,
                    columns: tuple[tuple[str, str, str], ...]) -> list[str]:
    """A table of the detector's figures per condition (the same for every tracker: the first
    tracker's row), ``columns`` (heading, key, format; '%': a share in per cent), the
    conditions without the first key left out."""
    lines = [intro, "", "| condition | " + " | ".join(c[0] for c in columns) + " |",
             "|---" * (len(columns) + 1) + "|"]
    for condition, rows in acc.items():
        m = next(iter(rows.values()))
        if columns[0][1] not in m:
            continue
        cells = [f"{_f(100 * m[key], '.1f')}%" if fmt == "%" else _f(m[key], fmt)
                 for _, key, fmt in columns]
        lines.append(f"| {condition} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def summary_lines(acc: dict[str, dict[str, dict[str, float]]]) -> list[str]:
    """The default tracker against the issue's acceptance targets."""
    if "clean" not in acc or "default" not in acc["clean"]:
        return []
    clean = acc["clean"]["default"]
    worse = []
    for condition, rows in acc.items():
        m = rows.get("default")
        if m is None or condition == "clean" or condition.startswith("all"):
            continue
        ratio = m["rot"] / clean["rot"] if clean["rot"] > 0 else np.inf
        if not np.isfinite(m["rot"]):
            worse.append(f"{condition} (no estimate)")
        elif ratio > 1.5:
            worse.append(f"{condition} {ratio:.1f}x")
    out = [
        f"- Each effect alone within 1.5x the clean orientation RMSE ({clean['rot']:.2f} deg): "
        + ("yes" if not worse else "no: " + ", ".join(worse)) + "."
    ]
    combined = {c: rows for c, rows in acc.items() if c.startswith("all") and "default" in rows}
    for c, rows in combined.items():
        m = rows["default"]
        smoothed = rows.get(SMOOTHED, {}).get("rom", np.nan)
        targets = [
            ("<= 1.0 deg", m["rot"] <= 1.0), ("<= 2 mm", m["pos"] <= 2.0),
            ("RoM <= 1.0 deg", m["rom"] <= 1.0), ("recall >= 98%", m["recall"] >= 0.98),
            ("coverage >= 99%", m["cover"] >= 0.99),
        ]
        if np.isfinite(smoothed):
            targets.append(("smoothed RoM <= 0.7 deg", smoothed <= 0.7))
        missed = [name for name, ok in targets if not ok]
        out.append(
            f"- {c}: {m['rot']:.2f} deg, {m['pos']:.1f} mm, RoM {m['rom']:.2f} deg"
            + (f" (smoothed {smoothed:.2f})" if np.isfinite(smoothed) else "")
            + f", recall {100 * m['recall']:.1f}%, coverage {100 * m['cover']:.1f}%: "
            + ("meets every target." if not missed else "misses " + ", ".join(missed) + ".")
        )
    left = [c for c in acc if "left" in c and "default" in acc[c]]
    if left:
        wrong = max(acc[c]["default"]["wrong_side"] for c in left)
        out.append(f"- Left hands reported as right: {100 * wrong:.1f}% of estimated frames "
                   "at worst (target 0).")
    return out
