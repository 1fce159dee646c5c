"""An honest paper baseline (issue 12 item 4): the paper's filter at its best, and the paper end
to end.

The paper's configuration (`--model paper`: Euler-angle state, per-blob association, depth only
at initialisation) has one process-noise value nobody tuned, and a Z-Y-Z Euler state that is
singular at the neutral start pose. Here:

- both Euler conventions: Z-Y-Z (`paper`) and the roll-pitch-yaw its figure legend implies
  (`paper_rpy`, intrinsic Z-Y-X, singular at pitch +-90 deg);
- the process noise (orientation random walk and linear acceleration densities) chosen by a
  grid sweep on *tuning* recordings that are not the test recordings: measurement-level
  simulations of recorded hand motion (../shared/realdata: a tennis serve's ball toss, the two
  wheelchair-racing gloves slowed 0.3x and shrunk 0.2x);
- then scored on the test recordings, the scripted scenarios (seeds 0..), beside the untuned
  value and our default tracker.

- with a bench cache, the same configurations on rendered RGB-D recordings of the scripted
  scenarios through our detector (`wristtrack track` on the images): the paper's filter on
  our detector (a skin ROI + Bhattacharyya detector, with our refinements), initialised
  automatically and, as the paper does, from manual labels of the first frame (a perfect
  operator's: the renderer's true marker centres);
- and the paper end to end: its tuned filter on its own detector (`--detector paper`:
  section III-A as published, without our sub-pixel weighting, blob splitting, shape tests,
  skin gate, colour learning, tracked window or streak model; detect/paper.py), initialised
  from the manual labels as the paper is, and automatically for comparison (where the two
  differ, the paper's detector misled our automatic initialisation).

``paper_baseline_section(quick)`` returns Markdown lines; ``python -m benchmarks.paper_baseline``
prints them.
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from pathlib import Path

import numpy as np

from wristtrack.sim.detections import acceptance_noise, simulate_detections
from wristtrack.sim.motion import SCENARIOS
from wristtrack.sim.scenario_run import score_run, track_scenario
from wristtrack.tracking.models import ProcessNoise
from wristtrack.tracking.tracker import Tracker, TrackerConfig

KTK = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "kineticstoolkit"
SLOW = {"speed": 0.3, "position_scale": 0.2, "rotation_scale": 0.2}
TUNING = (
    ("tennis toss", "kinematics_tennis_serve.c3d", "RWRA,RWRB,RFIN",
     {"start_s": 1.0, "duration_s": 1.6}),
    ("racing glove R", "kinematics_racing_propulsion.c3d", "GloveR1,GloveR2,GloveR3",
     {"start_s": 0.0, "duration_s": 1.0, **SLOW}),
    ("racing glove L", "kinematics_racing_propulsion.c3d", "GloveL1,GloveL2,GloveL3",
     {"start_s": 2.0, "duration_s": 1.0, **SLOW}),
)
ANGULAR_RATE = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0)  # (rad/s)^2 s
LINEAR_ACCEL = (0.03, 0.1, 0.3, 1.0)  # (m/s^2)^2 s
MODELS = {"paper": "Z-Y-Z (paper)", "paper_rpy": "roll-pitch-yaw (paper_rpy)"}


def tuning_runs(seed: int = 100):
    """(name, truth, camera, layout, frames) of each tuning recording at measurement level."""
    from wristtrack.sim.recorded import load_recorded_motion, recorded_scene

    out = []
    for k, (name, file, cluster, options) in enumerate(TUNING):
        rec = load_recorded_motion(KTK / file, cluster.split(","), **options)
        scene = recorded_scene(rec, 30.0)
        truth = scene.trajectory()
        rng = np.random.default_rng(seed + k)
        frames = simulate_detections(truth, scene.camera, scene.layout,
                                     acceptance_noise(len(truth.t)), rng)
        out.append((name, truth, scene.camera, scene.layout, frames))
    return out


def _score(config: TrackerConfig, run) -> tuple[float, float, int]:
    name, truth, camera, layout, frames = run
    tracker = Tracker(camera, layout, config)
    result = score_run(name, truth, frames, [tracker.step(f.detections) for f in frames])
    e = result.errors
    return e.orientation_rmse_deg, e.position_rmse_mm, result.lost_frames


def sweep(model: str, runs, rates=ANGULAR_RATE, accels=LINEAR_ACCEL) -> dict:
    """Mean tuning orientation / position RMSE per (angular_rate, linear_accel); NaN-safe."""
    table = {}
    for q, a in itertools.product(rates, accels):
        config = TrackerConfig.paper(model=model,
                                     process=ProcessNoise(angular_rate=q, linear_accel=a))
        scores = np.array([_score(config, run) for run in runs], dtype=float)
        table[(q, a)] = (float(np.mean(scores[:, 0])), float(np.mean(scores[:, 1])),
                         int(scores[:, 2].sum()))
    return table


def _best(table: dict) -> tuple[float, float]:
    """The setting with the lowest mean orientation RMSE (ties: the lower position RMSE)."""
    return min(table, key=lambda k: (np.nan_to_num(table[k][0], nan=1e9), table[k][1]))


def test_scores(config: TrackerConfig, seeds) -> dict[str, tuple[float, float, float]]:
    """Per scenario: mean orientation RMSE (deg), position RMSE (mm), failure rate."""
    out = {}
    for name in SCENARIOS:
        runs = [track_scenario(name, config, seed=s) for s in seeds]
        out[name] = (float(np.mean([r.errors.orientation_rmse_deg for r in runs])),
                     float(np.mean([r.errors.position_rmse_mm for r in runs])),
                     float(np.mean([r.errors.failure_rate for r in runs])))
    return out


RENDERED = ("deviation", "flexion", "pronation", "reach")


def rendered_rows(configs: dict[str, TrackerConfig], cache: Path, quick: bool) -> list[str]:
    """The configurations on rendered recordings through our detector, the tuned ones also
    through the paper's (evaluate's figures); the table and what it shows."""
    import tempfile

    from benchmarks.pipeline import rendered_recordings
    from wristtrack.analysis.evaluate import evaluate
    from wristtrack.errors import InitialisationError
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.track import track_recording

    recordings = rendered_recordings(cache, n_frames=40 if quick else None)
    tuned = {label: config for label, config in configs.items() if "tuned (" in label}
    runs = [(label, config, False, "default") for label, config in configs.items()]
    runs += [(f"{label}, manual labels", config, True, "default")
             for label, config in tuned.items()]
    ends = {}  # (model label, manual) -> row label
    for manual in (False, True):
        for label in tuned:
            model = label.split(", tuned")[0]
            ends[model, manual] = (f"**the paper end to end**: its detector, {model} tuned, "
                                   + ("manual labels" if manual else "automatic initialisation"))
            runs.append((ends[model, manual], tuned[label], manual, "paper"))
    lines = [
        "### The paper's filter on our detector, and the paper end to end (rendered "
        "recordings; orientation RMSE deg / position RMSE mm / failure rate / coverage)",
        "",
        "Our detector unless the row says \"its detector\" (`--detector paper`: the paper's "
        "section III-A as published, detect/paper.py). Manual labels: the first frame's six "
        "marker centres as a perfect operator would click them (the renderer's truth).",
        "",
        "| configuration | " + " | ".join(RENDERED) + " |",
        "|---|" + "---|" * len(RENDERED),
    ]
    results: dict[str, list] = {}
    with tempfile.TemporaryDirectory() as work:
        for label, config, manual, detector in runs:
            cells, results[label] = [], []
            for name in RENDERED:
                run = Path(work) / f"{name}-{len(cells)}-{abs(hash(label))}"
                labels = manual_labels(recordings[name]) if manual else None
                with open_recording(recordings[name]) as recording:
                    try:
                        track_recording(recording, run, config, labels=labels, progress=False,
                                        detector=detector)
                    except InitialisationError:  # the cell says so, the table goes on
                        cells.append("never initialised")
                        results[label].append(None)
                        continue
                r = evaluate(run / "poses.csv", recordings[name] / "truth.csv")
                results[label].append(r)
                cells.append(
                    f"{_num(r['orientation_rmse_deg'])} / {_num(r['position_rmse_mm'], 1)} / "
                    f"{(r['failure_rate'] or 0):.0%} / {(r['coverage'] or 0):.0%}")
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return [*lines, "", *_end_to_end_findings(results, tuned, ends)]


def _mean_rot(rows: list) -> float | None:
    """Mean orientation RMSE (deg) over the recordings of a row; None unless all tracked."""
    values = [None if r is None else r["orientation_rmse_deg"] for r in rows]
    return None if any(v is None for v in values) else float(np.mean(values))


def _deg(x: float | None) -> str:
    return "n/a (not every recording tracked)" if x is None else f"{x:.2f} deg"


def _same(a, b) -> bool:
    keys = ("orientation_rmse_deg", "position_rmse_mm", "failure_rate", "coverage")
    return a is not None and b is not None and all(a[k] == b[k] for k in keys)


def _end_to_end_findings(results: dict, tuned: dict, ends: dict) -> list[str]:
    """What the end-to-end rows show, in sentences computed from them."""
    ours = _mean_rot(results["default tracker (ours)"])
    lines = [f"Mean orientation RMSE over the {len(RENDERED)} recordings: our default tracker "
             f"{_deg(ours)};"]
    parts, gaps = [], []
    for label in tuned:
        model = label.split(", tuned")[0]
        on_ours, on_its = _mean_rot(results[label + ", manual labels"]), \
            _mean_rot(results[ends[model, True]])
        parts.append(f"{model} tuned, manual labels: {_deg(on_ours)} on our detector, "
                     f"{_deg(on_its)} on its own")
        if None not in (ours, on_ours, on_its):
            gaps.append((model, on_ours - ours, on_its - ours))
    lines[0] += " " + "; ".join(parts) + "."
    for model, on_ours, on_its in gaps:
        verdict = ("the gap is the method's (its filter), not the detector's"
                   if abs(on_its - on_ours) <= 0.25 * min(on_ours, on_its)
                   else "the detector accounts for a share of it")
        lines.append(f"Gap to ours, {model}: {on_its:.2f} deg end to end, {on_ours:.2f} deg "
                     f"with our detector: {verdict}.")
    for label in tuned:
        model = label.split(", tuned")[0]
        auto, manual = results[ends[model, False]], results[ends[model, True]]
        differ = [n for n, a, m in zip(RENDERED, auto, manual, strict=True) if not _same(a, m)]
        if differ:
            lines.append(f"With its detector and {model}, automatic initialisation and the "
                         f"manual labels differ on {', '.join(differ)}: there the automatic "
                         "initialisation on the paper's blobs fixed another frame or labelled "
                         "it otherwise (or never fixed one); the manual-label row is the "
                         "paper's figure.")
        else:
            lines.append(f"With its detector and {model}, automatic initialisation gives the "
                         "same figures as the manual labels on every recording: the automatic "
                         "labelling of the first frame was right on the paper's blobs too.")
    lines.append("These are the scripted renders without the realism effects; where our "
                 "detector's refinements matter (a merged pair of markers: one blob between "
                 "them; clutter under warm light: passed to the tracker) is shown by "
                 "tests/detect/test_paper_detector.py, not in these figures.")
    return [" ".join(lines), ""]


def manual_labels(recording: Path):
    """The paper's initialisation: the six marker centres of the first frame clicked by hand,
    here as a perfect operator would (the renderer's true centres, truth_markers.csv)."""
    import csv

    from wristtrack.hand import MARKER_NAMES
    from wristtrack.pipeline.label import ManualLabels

    with open(recording / "truth_markers.csv", newline="") as fh:
        row = next(csv.DictReader(fh))
    uv = np.array([[float(row[f"{n}_u"]), float(row[f"{n}_v"])] for n in MARKER_NAMES])
    return ManualLabels(frame=0, timestamp=float(row["timestamp"]), markers=uv, blobs=uv.copy(),
                        source="truth_markers.csv")


def _num(x, digits: int = 2) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def paper_baseline_section(quick: bool = False, findings: dict | None = None,
                           cache: Path | None = None) -> list[str]:
    if not KTK.is_dir():
        return ["## The paper at its best", "", f"Skipped: {KTK} not found.", ""]
    runs = tuning_runs()
    rates = ANGULAR_RATE[1::2] if quick else ANGULAR_RATE
    accels = LINEAR_ACCEL[1:3] if quick else LINEAR_ACCEL
    seeds = (0,) if quick else (0, 1, 2)
    default_noise = ProcessNoise()
    sweeps = {m: sweep(m, runs, rates, accels) for m in MODELS}
    best = {m: _best(t) for m, t in sweeps.items()}
    lines = [
        "## The paper at its best, and end to end (issue 12 item 4)",
        "",
        "The paper's configuration (Euler state, per-blob association, depth only at "
        "initialisation) with its process noise chosen by a sweep on tuning recordings "
        "(measurement-level simulations of recorded motion: "
        + ", ".join(name for name, *_ in TUNING)
        + f"; seeds 100-102) that are not the test recordings (the scripted scenarios, seeds "
        f"{list(seeds)}). Untuned: angular_rate {default_noise.angular_rate}, linear_accel "
        f"{default_noise.linear_accel}.",
        "",
        "### Sweep on the tuning recordings (mean orientation RMSE, deg; position RMSE, mm)",
        "",
        "| angular_rate \\ linear_accel | " + " | ".join(
            f"{MODELS[m].split(' (')[0]} {a}" for m in MODELS for a in accels) + " |",
        "|---|" + "---|" * (len(MODELS) * len(accels)),
    ]
    for q in rates:
        cells = []
        for m in MODELS:
            for a in accels:
                rot, pos, _ = sweeps[m][(q, a)]
                mark = " **best**" if best[m] == (q, a) else ""
                cells.append(f"{rot:.2f} / {pos:.1f}{mark}")
        lines.append(f"| {q} | " + " | ".join(cells) + " |")
    spread = {m: np.nanmax([v[0] for v in t.values()]) / np.nanmin([v[0] for v in t.values()])
              for m, t in sweeps.items()}
    lines += [
        "",
        "Across the grid the tuning orientation RMSE varies "
        + ", ".join(f"{spread[m]:.1f}x ({MODELS[m]})" for m in MODELS) + ".",
        "",
        "### Test recordings (scripted scenarios; orientation RMSE deg / position RMSE mm / "
        "share of frames beyond 10 deg or 20 mm)",
        "",
        "| configuration | " + " | ".join(SCENARIOS) + " |",
        "|---|" + "---|" * len(SCENARIOS),
    ]
    configs = {"default tracker (ours)": TrackerConfig()}
    for m, label in MODELS.items():
        q, a = best[m]
        configs[f"{label}, untuned"] = TrackerConfig.paper(model=m)
        configs[f"{label}, tuned (angular_rate {q}, linear_accel {a})"] = TrackerConfig.paper(
            model=m, process=replace(default_noise, angular_rate=q, linear_accel=a))
    results = {}
    for label, config in configs.items():
        results[label] = test_scores(config, seeds)
        lines.append(f"| {label} | " + " | ".join(
            f"{r:.2f} / {p:.1f} / {f:.0%}" for r, p, f in results[label].values()) + " |")
    if findings is not None:
        findings["paper_baseline"] = {"best": best, "results": results}
    lines.append("")
    if cache is not None:
        lines += rendered_rows(configs, cache, quick)
    return lines


if __name__ == "__main__":
    import sys
    import tempfile

    print("\n".join(paper_baseline_section(
        quick="--quick" in sys.argv, cache=Path(tempfile.gettempdir()) / "wristtrack-bench")))
