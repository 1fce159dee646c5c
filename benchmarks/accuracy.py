"""Benchmark against the peers and the physical limit, on the measurement-level simulator.

Every tracker gets the same detections (``simulate_detections`` with the acceptance noise, one
draw per scenario and seed) and is scored by the same code (``metrics.pose_errors`` plus the
range-of-motion error as ``wristtrack evaluate`` computes it). The per-frame Cramér-Rao bound
(``crlb.pose_crlb``) is evaluated at the true pose of each frame, for the markers detected in
that frame, under the simulator's own noise (``NoiseModel``: pixel sigma, depth sigma c z^2
without floor).

Adding a row to the accuracy table is one entry in ``ACCURACY_ROWS``: a label and a
:class:`Row` whose ``run`` maps (camera, layout, detections) to one ``FrameResult`` per frame.
An offline method (a smoother) runs the whole list at once; ``online`` wraps a per-frame tracker.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from benchmarks.crlb import pose_crlb
from wristtrack.analysis.pose_errors import pose_errors
from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.geometry import wrist_angles
from wristtrack.hand import HandLayout
from wristtrack.sim.detections import NoiseModel, SimFrame, acceptance_noise, simulate_detections
from wristtrack.sim.motion import SCENARIOS, Trajectory, scenario
from wristtrack.tracking.layout_survey import RunSurvey
from wristtrack.tracking.noise_scale import primes
from wristtrack.tracking.tracker import FrameResult, Tracker, TrackerConfig

Runner = Callable[[Camera, HandLayout, list[Detections]], list[FrameResult]]


def online(factory: Callable[[Camera, HandLayout], object]) -> Runner:
    """A Runner stepping a per-frame tracker (anything with ``step(Detections)``) through."""

    def run(camera: Camera, layout: HandLayout, detections: list[Detections]):
        tracker = factory(camera, layout)
        return [tracker.step(d) for d in detections]

    return run


def _default_tracker(camera: Camera, layout: HandLayout | None, detections: list[Detections],
                     config: TrackerConfig | None = None) -> tuple[Tracker, list[FrameResult]]:
    """The default tracker (or one of ``config``) stepped through ``detections`` as
    ``wristtrack track`` runs it (pipeline/track.py, priming.py; here on the same detections):
    without a layout, a first pass surveys it over the recording and a second tracks with it;
    the pass that tracks starts from the noise a pass over the first PRIMING_S learned
    (TrackerConfig.prime_noise). The last pass's tracker and results."""
    return _default_run(camera, layout, detections, config)[:2]


def _default_run(camera: Camera, layout: HandLayout | None, detections: list[Detections],
                 config: TrackerConfig | None = None
                 ) -> tuple[Tracker, list[FrameResult], HandLayout | None]:
    """:func:`_default_tracker`'s last pass and the layout it tracked with: ``layout``, the
    surveyed one, or None (nothing surveyed: the survey's pass, on the still start's)."""
    config = TrackerConfig() if config is None else config
    if layout is None:
        tracker, results, layout = _survey(camera, detections, config)
        if layout is None:  # nothing surveyed: the first pass is the run
            return tracker, results, None
    return (*_tracking_pass(camera, layout, detections, config), layout)


def _survey(camera: Camera, detections: list[Detections], config: TrackerConfig):
    """The first pass without a layout: its tracker, results and the layout it surveyed (None:
    nothing)."""
    survey = RunSurvey()
    tracker = Tracker(camera, None, config)
    results = []
    for d in detections:
        results.append(tracker.step(d))
        survey.add(tracker, d, results[-1])
    return tracker, results, survey.surveyed_layout()


def _tracking_pass(camera: Camera, layout: HandLayout | None, detections: list[Detections],
                   config: TrackerConfig) -> tuple[Tracker, list[FrameResult]]:
    """One pass that tracks with ``layout`` (None: the still start's), primed."""
    tracker = Tracker(camera, layout, config)
    if config.primes_noise and detections:
        first = Tracker(camera, layout, config)
        for d in detections:
            if not primes(d.timestamp, detections[0].timestamp):
                break
            first.step(d)
        tracker.start_from(first.learned_noise)
    return tracker, [tracker.step(d) for d in detections]


def _default(camera: Camera, layout: HandLayout | None, detections: list[Detections]):
    return _default_tracker(camera, layout, detections)[1]


def _smoothed(camera: Camera, layout: HandLayout | None, detections: list[Detections],
              config: TrackerConfig | None = None):
    """The default tracker (or one of ``config``), then the offline unscented RTS smoother over
    its results; with ``config.smoothing_noise`` "learned", tracked again at the angular
    process noise those smoothed rates show and smoothed, as ``track --smooth --smooth-noise
    learned`` does (pipeline/refit.py; the refit tracks with the first run's layout, surveyed
    or given)."""
    from wristtrack.tracking.smoothed_results import smooth_results
    from wristtrack.tracking.smoother_noise import keeps_refit, refits, results_angular_accel

    config = TrackerConfig() if config is None else config
    tracker, results, used = _default_run(camera, layout, detections, config)
    first = smooth_results(tracker.model, results, config.ukf, config.coast_limit)
    q = results_angular_accel(first, config.process.angular_accel) if refits(config) else None
    if q is None:
        return first
    again = replace(config, process=replace(config.process, angular_accel=q))
    tracker, results = _tracking_pass(camera, used, detections, again)
    refit = smooth_results(tracker.model, results, again.ukf, again.coast_limit)
    tracked = [sum(r.has_estimate for r in run) for run in (first, refit)]
    return refit if keeps_refit(*tracked) else first


def _smoothed_learned(camera: Camera, layout: HandLayout | None,
                      detections: list[Detections]):
    return _smoothed(camera, layout, detections, TrackerConfig(smoothing_noise="learned"))


def _slide_as_noise(camera: Camera, layout: HandLayout | None, detections: list[Detections]):
    return _default_tracker(camera, layout, detections, TrackerConfig(follow_slide=False))[1]


def _slide_as_noise_smoothed(camera: Camera, layout: HandLayout | None,
                             detections: list[Detections]):
    return _smoothed(camera, layout, detections, TrackerConfig(follow_slide=False))


def _opencv(camera: Camera, layout: HandLayout):
    from benchmarks.peers.opencv_pnp import OpenCVPnPTracker

    return OpenCVPnPTracker(camera, layout)


def _stonesoup(camera: Camera, layout: HandLayout):
    from benchmarks.peers.stonesoup_ukf import StoneSoupTracker  # the bench extra

    return StoneSoupTracker(camera, layout)


@dataclass(frozen=True)
class Row:
    """One tracker configuration of the accuracy table. ``max_frames`` limits each run to the
    first frames of every scenario (for slow peers; the table says so); ``ours`` marks the
    product's own rows, which the summary does not count as baselines."""

    run: Runner
    max_frames: int | None = None
    ours: bool = False


DEFAULT = "default"
# the default with the skin slide as noise the markers share, not in the state (wristtrack
# track --no-follow-slide; the default before the slide state)
AS_NOISE = "default, skin slide as shared noise"
AS_NOISE_SMOOTHED = "default, skin slide as shared noise, + smoother (offline)"
# track --smooth --smooth-noise learned (pipeline/refit.py)
LEARNED_SMOOTHED = "default + smoother at the learned noise (offline)"
TIE = 0.01  # relative difference below which the summary calls two errors a tie
ACCURACY_ROWS: dict[str, Row] = {
    DEFAULT: Row(_default, ours=True),
    "default + smoother (offline)": Row(_smoothed, ours=True),
    LEARNED_SMOOTHED: Row(_smoothed_learned, ours=True),
    AS_NOISE: Row(_slide_as_noise, ours=True),
    AS_NOISE_SMOOTHED: Row(_slide_as_noise_smoothed, ours=True),
    "paper model, paper's rule": Row(online(lambda c, lay: Tracker(c, lay, TrackerConfig.paper()))),
    "OpenCV per-frame (IPPE PnP)": Row(online(_opencv)),
    "Stone Soup UKF + PDA": Row(online(_stonesoup)),
}


@dataclass(frozen=True)
class SimCase:
    """One simulated recording: its truth and the detections every tracker gets."""

    name: str
    seed: int
    truth: Trajectory
    camera: Camera
    layout: HandLayout
    frames: list[SimFrame]
    noise: NoiseModel


NEAR_CLUTTER = "mix, clutter beside markers"
CASES = (*SCENARIOS, NEAR_CLUTTER)


def sim_case(name: str, seed: int, noise: NoiseModel | None = None) -> SimCase:
    """Scenario ``name`` (one of CASES) with the acceptance noise (or ``noise``), drawn as
    track_scenario does. NEAR_CLUTTER is ``mix`` with 1.5 more blobs per frame within ~8 px of
    random markers, at their depth +- 1 cm (the association stress of the main benchmark)."""
    rng = np.random.default_rng(seed)
    motion = "mix" if name == NEAR_CLUTTER else name
    truth, camera, layout = scenario(motion, rng=rng)
    if noise is None:
        noise = acceptance_noise(len(truth.t))
        if name == NEAR_CLUTTER:
            noise = replace(noise, near_clutter_mean=1.5, near_clutter_px=8.0)
    frames = simulate_detections(truth, camera, layout, noise, rng)
    return SimCase(name, seed, truth, camera, layout, frames, noise)


def clean_noise() -> NoiseModel:
    """Sensor noise only (pixels and depth as in the acceptance setting): no clutter, no misses."""
    return NoiseModel(clutter_mean=0.0, p_miss=0.0)


def _head(truth: Trajectory, n: int) -> Trajectory:
    return Trajectory(*(getattr(truth, f)[:n] for f in Trajectory.__dataclass_fields__))


def score(results: list[FrameResult], truth: Trajectory) -> dict[str, float]:
    """Pose errors, failure rate, coverage, and the worst range-of-motion error over the three
    anatomical axes (estimated range over the frames with an estimate against the true range,
    as ``wristtrack evaluate``)."""
    R = np.stack([r.R_ch for r in results])
    t = np.stack([r.t_ch for r in results])
    n = len(results)
    e = pose_errors(R, t, truth.R_ch[:n], truth.t_ch[:n])
    rom = float(np.max(np.abs(range_errors(results, truth))))
    return {
        "rot": e.orientation_rmse_deg, "rot95": e.orientation_p95_deg, "pos": e.position_rmse_mm,
        "rom": rom, "fail": e.failure_rate, "cover": e.coverage, "frames": n,
    }


def range_errors(results: list[FrameResult], truth: Trajectory) -> np.ndarray:
    """(3,) estimated minus true range of each anatomical axis (deviation, flexion, pronation),
    degrees: the estimate's over the frames with one, the truth's over all the frames (as
    ``wristtrack evaluate``); NaN where fewer than two frames have an estimate."""
    rel = np.stack([r.R for r in results])
    ok = np.isfinite(rel).all(axis=(1, 2))
    if ok.sum() < 2:
        return np.full(3, np.nan)
    est = np.degrees(wrist_angles(rel[ok]))
    true = np.degrees(truth.angles[: len(results)])
    return np.ptp(est, axis=0) - np.ptp(true, axis=0)


def bound(case: SimCase, n: int | None = None, depth: bool = True) -> np.ndarray:
    """Per-frame bound covariances (N,6,6) of the case's first ``n`` frames."""
    frames = case.frames[:n]
    vis = np.zeros((len(frames), case.layout.points.shape[0]), bool)
    has_depth = np.zeros_like(vis)
    for k, f in enumerate(frames):
        marker = f.labels >= 0
        vis[k, f.labels[marker]] = True
        if depth and f.detections.depth is not None:
            has_depth[k, f.labels[marker]] = np.isfinite(f.detections.depth[marker])
    m = len(frames)
    return pose_crlb(
        case.camera, case.layout.points, case.truth.R_ch[:m], case.truth.t_ch[:m], vis,
        has_depth, case.noise.pixel_sigma, case.noise.depth_sigma_coeff, 0.0,
    ).cov


def _rms_bound(covs: list[np.ndarray]) -> tuple[float, float]:
    """(orientation deg, position mm) RMS of the bound's std over all observable frames."""
    cov = np.concatenate(covs)
    cov = cov[np.isfinite(cov).all(axis=(1, 2))]
    rot = np.degrees(np.sqrt(np.mean(np.trace(cov[:, :3, :3], axis1=1, axis2=2))))
    pos = 1e3 * np.sqrt(np.mean(np.trace(cov[:, 3:, 3:], axis1=1, axis2=2)))
    return float(rot), float(pos)


def _f(x: float, fmt: str = ".2f") -> str:
    return "n/a" if x is None or not np.isfinite(x) else format(x, fmt)


def accuracy_sections(
    seeds: tuple[int, ...],
    rows: dict[str, Row] | None = None,
    findings: dict | None = None,
    max_frames: int | None = None,
) -> list[str]:
    """The accuracy table of every row on every scenario, and the bound table.

    ``max_frames`` caps every run (the --quick mode); a row's own cap applies on top.
    ``findings`` receives per-scenario figures for the summary.
    """
    rows = ACCURACY_ROWS if rows is None else rows
    findings = {} if findings is None else findings
    acc: dict[str, dict[str, dict]] = {}
    lines = [
        "| scenario | tracker | rot RMSE (deg) | rot p95 (deg) | pos RMSE (mm) | worst RoM error "
        "(deg) | failure rate | coverage | rot RMSE / bound | pos RMSE / bound |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    limited = []
    bounds: dict[str, tuple] = {}
    for name in CASES:
        cases = [sim_case(name, s) for s in seeds]
        full = len(cases[0].frames) if max_frames is None else min(max_frames, len(cases[0].frames))
        b_rot, b_pos = _rms_bound([bound(c, full) for c in cases])
        px_rot, px_pos = _rms_bound([bound(c, full, depth=False) for c in cases])
        # the clean version of NEAR_CLUTTER would be mix's again
        clean = [] if name == NEAR_CLUTTER else [sim_case(name, s, clean_noise()) for s in seeds]
        c_rot, c_pos = _rms_bound([bound(c, full) for c in clean]) if clean else (np.nan, np.nan)
        clean_runs = [
            score(rows[DEFAULT].run(c.camera, c.layout, [f.detections for f in c.frames[:full]]),
                  c.truth)
            for c in clean
        ] if DEFAULT in rows else []
        clean_rot = float(np.mean([r["rot"] for r in clean_runs])) if clean_runs else np.nan
        clean_pos = float(np.mean([r["pos"] for r in clean_runs])) if clean_runs else np.nan
        bounds[name] = (b_rot, b_pos, px_rot, px_pos, c_rot, c_pos, clean_rot, clean_pos)
        acc[name] = {}
        for label, row in rows.items():
            n = full if row.max_frames is None else min(full, row.max_frames)
            if n < full:
                limited.append(f"{label}: first {n} frames of each scenario")
                nb_rot, nb_pos = _rms_bound([bound(c, n) for c in cases])
            else:
                nb_rot, nb_pos = b_rot, b_pos
            runs = [
                score(row.run(c.camera, c.layout, [f.detections for f in c.frames[:n]]),
                      _head(c.truth, n))
                for c in cases
            ]
            r = {k: float(np.mean([x[k] for x in runs])) for k in runs[0]}
            r["rot_ratio"], r["pos_ratio"] = r["rot"] / nb_rot, r["pos"] / nb_pos
            acc[name][label] = r
            lines.append(
                f"| {name} | {label} | {_f(r['rot'], '.3f')} | {_f(r['rot95'])} | "
                f"{_f(r['pos'], '.3f')} | "
                f"{_f(r['rom'])} | {100 * r['fail']:.1f}% | {100 * r['cover']:.1f}% | "
                f"{_f(r['rot_ratio'])} | {_f(r['pos_ratio'])} |"
            )
    findings["accuracy"], findings["bounds"] = acc, bounds
    findings["ours"] = [k for k, r in rows.items() if r.ours]

    bound_lines = [
        "| scenario | bound rot (deg) | bound pos (mm) | pixels-only bound rot (deg) | "
        "pixels-only bound pos (mm) | clean: bound rot (deg) | clean: default rot RMSE (deg) "
        "| clean: ratio | clean: bound pos (mm) | clean: default pos RMSE (mm) | clean: ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (b_rot, b_pos, px_rot, px_pos, c_rot, c_pos, d_rot, d_pos) in bounds.items():
        bound_lines.append(
            f"| {name} | {b_rot:.3f} | {b_pos:.3f} | {px_rot:.2f} | {px_pos:.2f} | "
            f"{_f(c_rot, '.3f')} | {_f(d_rot, '.3f')} | {_f(d_rot / c_rot)} | {_f(c_pos, '.3f')} | "
            f"{_f(d_pos, '.3f')} | {_f(d_pos / c_pos)} |"
        )
    seeds_text = f"seeds {list(seeds)}" + (f", first {max_frames} frames" if max_frames else "")
    note = (" Limited: " + "; ".join(sorted(set(limited))) + ".") if limited else ""
    return [
        "## Accuracy against the peers (measurement-level simulator)",
        "",
        "The same detections for every tracker: acceptance noise "
        f"({NoiseModel().pixel_sigma:g} px blob noise, the filter's own pixel model; Poisson "
        "clutter of 3 blobs per frame, 10% missed detections, MCP4 and MCP5 occluded for 10 "
        "frames, depth noise 1.425e-3 z^2 m), " + seeds_text + ", mean over seeds. Rows: "
        "`default` is the product; `paper model, paper's rule` the paper's method (Euler-angle "
        "state, per-blob association, depth only to initialise); `OpenCV per-frame` labels each "
        "frame's blobs by the best 3-D layout fit and solves `cv2.solvePnP` (planar IPPE, then "
        "LM) on the pixels, no temporal filter (`benchmarks.peers.opencv_pnp`); `Stone Soup "
        "UKF + PDA` is Stone Soup's unscented Kalman predictor/updater with its PDA associator on "
        "our motion and measurement models, orientation as a rotation vector relative to the "
        "initial pose (`benchmarks.peers.stonesoup_ukf`). RoM error: worst of the three "
        "anatomical axes. The ratio columns divide the RMSE by the RMS of the per-frame "
        "Cramér-Rao bound (next section) over the same frames." + note,
        "",
        *lines,
        "",
        "## The physical limit: per-frame Cramér-Rao bound",
        "",
        "The bound on any unbiased estimate of one frame's pose from that frame's marker "
        "projections and depths, at the true pose, for the markers detected in the frame, under "
        "the simulator's noise (`benchmarks.crlb`; RMS over frames of the std of the geodesic "
        "angle and of the position). *Pixels-only* leaves the depths out (what PnP can use). "
        "*Clean* is the same motion with sensor noise only (no clutter, no misses): the target "
        "is the default tracker's orientation RMSE within 1.5x of the bound there. A filter "
        "pools frames through its motion model, so it can go below this per-frame bound "
        "(ratio < 1); a per-frame method cannot.",
        "",
        *bound_lines,
        "",
    ]


def lead_line(acc: dict, ours: set, where: str) -> str:
    """Per peer: on how many scenarios the default is ahead (orientation and position errors
    both lower by more than TIE), tied, or behind (either higher by more than TIE)."""
    names = [n for n in acc if DEFAULT in acc[n]]
    peers = [p for p in acc[names[0]] if p not in ours] if names else []
    parts, all_ahead = [], True
    for peer in peers:
        ahead, behind, worst = 0, 0, None
        for n in names:
            d, r = acc[n][DEFAULT], acc[n][peer]
            ratios = {}
            for key in ("rot", "pos"):
                ok = np.isfinite(d[key])
                ratios[key] = d[key] / r[key] if ok and np.isfinite(r[key]) else (0.0 if ok
                                                                                   else np.inf)
            if max(ratios.values()) < 1 - TIE:
                ahead += 1
            elif max(ratios.values()) > 1 + TIE:
                behind += 1
            key = max(ratios, key=ratios.get)
            if worst is None or ratios[key] > worst[0]:
                worst = (ratios[key], n, key, d[key], r[key])
        unit = {"rot": "deg", "pos": "mm"}
        what = {"rot": "orientation", "pos": "position"}
        if ahead == len(names):
            low = min(acc[n][peer]["rot"] / acc[n][DEFAULT]["rot"] for n in names)
            parts.append(f"ahead of {peer} on all {len(names)} (its orientation RMSE at least "
                         f"{low:.2f}x ours)")
            continue
        all_ahead = False
        _, n, key, dv, rv = worst
        parts.append(
            f"vs {peer}: ahead on {ahead}, tied (within {TIE:.0%}) on "
            f"{len(names) - ahead - behind}, behind on {behind} of {len(names)} (closest or "
            f"worst: {n}, {what[key]} {_f(dv, '.3f')} vs {_f(rv, '.3f')} {unit[key]})"
        )
    verdict = "met" if all_ahead else "**not met**"
    return (f"- Accuracy against the peers ({where}; target: more accurate than every baseline "
            f"on every scenario, {verdict}): " + "; ".join(parts) + ".")


def summary_lines(f: dict) -> list[str]:
    """Plain-language findings on the peers and the bound, from ``accuracy_sections``'
    findings (the rendered recordings' lead line is the rendered section's)."""
    acc, bounds, ours = f["accuracy"], f["bounds"], set(f["ours"])
    out = [lead_line(acc, ours, "same detections, measurement-level simulator")]
    ratios = {n: b[6] / b[4] for n, b in bounds.items() if np.isfinite(b[6] / b[4])}
    worst = max(ratios, key=ratios.get)
    met = all(r <= 1.5 for r in ratios.values())
    out.append(
        f"- Physical limit: on clean recordings (sensor noise only) the default orientation RMSE "
        f"is {min(ratios.values()):.2f}-{max(ratios.values()):.2f}x the per-frame Cramér-Rao "
        f"bound (worst: {worst}, {_f(bounds[worst][6])} vs {bounds[worst][4]:.3f} deg); target "
        f"<= 1.5x: " + ("met" if met else "**not met**") + ". Below 1 means the motion model "
        "pools information across frames, which a per-frame method cannot do."
    )
    return out


# ------------------------------------------------------------------ rendered RGB-D recordings


def recorded_detections(
    recording_dir, times: list[float] | None = None
) -> tuple[Camera, HandLayout | None, list, Trajectory]:
    """The detector's output on every frame of a rendered recording, as ``track`` produces it
    (the detector learns its colours at the default tracker's first fix and adapts them as the
    run goes on, by ``track``'s own rule, so the default tracker run on these detections is
    exactly ``track``), with the truth. ``times`` collects each frame's detection time (s)."""
    from wristtrack.detect.detector import MarkerDetector
    from wristtrack.io.open import open_recording
    from wristtrack.io.poses import read_poses, rows_to_poses
    from wristtrack.pipeline.colours import follow_colours

    with open_recording(recording_dir) as recording:
        camera, hand = recording.camera, recording.hand
        detector = MarkerDetector(camera)
        tracker = Tracker(camera, hand, TrackerConfig())
        learned = False
        detections = []
        for frame in recording:
            start = time.perf_counter()
            det = detector.detect(frame.bgr, frame.depth, frame.timestamp)
            if times is not None:
                times.append(time.perf_counter() - start)
            detections.append(det)
            result = tracker.step(det)
            learned = follow_colours(detector, frame.bgr, det, result, frame.index, learned)
    cols = read_poses(recording_dir / "truth.csv")
    R_ch, t_ch = rows_to_poses(cols)
    angles = np.radians(np.column_stack([cols[f"{a}_deg"] for a in
                                         ("deviation", "flexion", "pronation")]))
    nan = np.full_like(t_ch, np.nan)
    truth = Trajectory(cols["timestamp"], R_ch, t_ch, R_ch, t_ch, nan, nan, angles)
    return camera, hand, detections, truth


def rendered_sections(
    recordings: dict, rows: dict[str, Row] | None = None, findings: dict | None = None
) -> list[str]:
    """Every row of the accuracy table on the detections of every rendered recording."""
    rows = ACCURACY_ROWS if rows is None else rows
    findings = {} if findings is None else findings
    acc: dict[str, dict[str, dict]] = {}
    limited = []
    lines = [
        "| scenario | tracker | rot RMSE (deg) | rot p95 (deg) | pos RMSE (mm) | worst RoM error "
        "(deg) | failure rate | coverage |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, folder in recordings.items():
        camera, hand, detections, truth = recorded_detections(folder)
        acc[name] = {}
        for label, row in rows.items():
            n = len(detections) if row.max_frames is None else min(len(detections),
                                                                    row.max_frames)
            if n < len(detections):
                limited.append(f"{label}: first {n} frames of each recording")
            r = score(row.run(camera, hand, detections[:n]), _head(truth, n))
            acc[name][label] = r
            lines.append(
                f"| {name} | {label} | {_f(r['rot'], '.3f')} | {_f(r['rot95'])} | "
                f"{_f(r['pos'], '.3f')} | {_f(r['rom'])} | {100 * r['fail']:.1f}% | "
                f"{100 * r['cover']:.1f}% |"
            )
    findings["rendered_accuracy"] = acc
    note = (" Limited: " + "; ".join(sorted(set(limited))) + ".") if limited else ""
    return [
        "## Accuracy against the peers on rendered RGB-D recordings",
        "",
        "The detector's output on each rendered recording (the same blobs for every tracker, as "
        "`track` detects them), scored against truth.csv. Without hand.json (`no_hand`) every "
        "tracker estimates the layout at its first fix; `rgb_only` has no depth (the OpenCV "
        "baseline then labels with all six markers only). No bound here: the detector's noise "
        "is not a known model." + note,
        "",
        *lines,
        "",
    ]
