"""Command-line interface: ``wristtrack COMMAND ...``.

Errors the user can fix are printed as one line (no traceback) with a non-zero exit code.
"""

from __future__ import annotations

import argparse
import sys

from wristtrack import __version__
from wristtrack.errors import WristtrackError
from wristtrack.filter.associate import METHODS
from wristtrack.tracking.models import MODELS


def _demo(args: argparse.Namespace) -> int:
    from wristtrack.pipeline.demo import run_demo

    run_demo(args.out, args.scenario, args.seed, _config(args), progress=not args.no_progress,
             smooth=not args.no_smooth)
    return 0


def _config(args: argparse.Namespace):
    from wristtrack.tracking.tracker import TrackerConfig

    if args.model in ("paper", "paper_rpy"):
        return TrackerConfig.paper(model=args.model)
    return TrackerConfig(association=args.association, use_depth=not args.no_depth)


def _track(args: argparse.Namespace) -> int:
    if args.live is not None:
        return _track_live(args)
    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.track import track_recording

    camera = Camera.load(args.camera) if args.camera else None
    hand = HandLayout.load(args.hand) if args.hand else None
    options = {
        k: v
        for k, v in (("color_topic", args.color_topic), ("depth_topic", args.depth_topic),
                     ("info_topic", args.info_topic))
        if v
    }
    source = args.input
    if source is None:
        raise WristtrackError("give a recording to track, or --live SOURCE for a camera")
    if args.view or args.record or args.port is not None:
        raise WristtrackError("--view, --port and --record are for --live SOURCE; a recording "
                              "is tracked offline")
    labels = None
    if args.labels:
        from wristtrack.pipeline.label import ManualLabels

        labels = ManualLabels.load(args.labels)
    if args.resume and args.overlay:
        raise WristtrackError(
            "--overlay cannot be combined with --resume (the video cannot be continued); "
            "resume without --overlay"
        )
    from wristtrack.pipeline.checkpoint import RunComplete

    try:
        with open_recording(source, camera=camera, hand=hand, **options) as recording, \
                _overlay(args.overlay, recording) as overlay:
            summary = track_recording(
                recording, args.out, _config(args), progress=not args.no_progress,
                smooth=args.smooth, overlay=overlay, resume=args.resume,
                checkpoint_every=args.checkpoint_every, labels=labels,
            )
    except RunComplete as done:
        print(f"wristtrack track: {done}")
        return 0
    except KeyboardInterrupt:
        print(f"wristtrack track: interrupted; {args.out} keeps every frame done so far; run "
              "the same command with --resume to continue", file=sys.stderr)
        return 130
    frames = summary["frames"]
    print(f"tracked {frames['tracked']} of {frames['total']} frames; wrote {args.out}/poses.csv "
          f"and {args.out}/summary.json")
    for axis, rom in summary["range_of_motion"].items():
        if rom["range_deg"] is not None:
            print(f"  {axis:<10} {rom['min_deg']:7.1f} .. {rom['max_deg']:6.1f} deg "
                  f"(range {rom['range_deg']:.1f})")
    if summary.get("kinematics"):
        from wristtrack.analysis.kinematics import format_reaches

        print(format_reaches(summary["kinematics"]))
    # Exports last: they read the run folder's final poses.csv (smoothed, if asked for).
    for fmt in dict.fromkeys(args.export or ()):
        _export_one(args.out, fmt, None, "mm")
    if args.overlay:
        print(f"wrote overlay video {args.overlay}")
    if not args.no_report:
        from wristtrack.report.html import write_report

        print(f"wrote {write_report(args.out)} (figures in {args.out}/figures)")
    return 0


def _track_live(args: argparse.Namespace) -> int:
    """``track --live SOURCE``: real time (pipeline.live), with the live page and recording."""
    import contextlib

    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.live_sources import open_live
    from wristtrack.pipeline.live import track_live

    if args.input:
        raise WristtrackError(f"give a recording ({args.input}) or --live SOURCE, not both")
    refused = [flag for flag, on in (("--resume", args.resume), ("--smooth", args.smooth),
                                     ("--labels", args.labels)) if on]
    if refused:
        raise WristtrackError(
            f"{', '.join(refused)} cannot be used with --live (live tracking is causal and runs "
            "once); add --record DIR and track that folder offline with them"
        )
    if args.port is not None and not args.view:
        raise WristtrackError("--port is the --view page's port; add --view")
    camera = Camera.load(args.camera) if args.camera else None
    hand = HandLayout.load(args.hand) if args.hand else None
    with open_live(args.live, camera=camera, hand=hand) as source, \
            _overlay(args.overlay, source) as overlay, contextlib.ExitStack() as stack:
        view = None
        if args.view:
            from wristtrack.pipeline.live_view import DEFAULT_PORT, LiveView

            layout = source.hand.points if source.hand is not None else None
            port = DEFAULT_PORT if args.port is None else args.port
            view = stack.enter_context(LiveView(source.camera, layout, port, str(source.source)))
            print(f"live view: {view.url} (Ctrl-C ends the session)", flush=True)
        summary, live = track_live(source, args.out, _config(args), record=args.record,
                                   view=view, overlay=overlay)
    if live.get("source_error"):
        print(f"wristtrack track: the camera stopped: {live['source_error']}", file=sys.stderr)
    frames, lat = live["frames"], live["latency_ms"]
    print(f"tracked {summary['frames']['tracked']} of {frames['total']} frames "
          f"({frames['dropped']} dropped); latency p50 {lat['p50']:.1f} ms, p95 {lat['p95']:.1f} "
          f"ms; wrote {args.out}/poses.csv, summary.json and live.json")
    if live.get("record"):
        rec = live["record"]
        print(f"recorded {rec['frames']} frames to {rec['folder']}"
              + (f" ({rec['lost']} lost: {rec['error'] or 'the disk fell behind'})"
                 if rec["lost"] else ""))
    for fmt in dict.fromkeys(args.export or ()):
        _export_one(args.out, fmt, None, "mm")
    if args.overlay:
        print(f"wrote overlay video {args.overlay}")
    if not args.no_report:
        from wristtrack.report.html import write_report

        print(f"wrote {write_report(args.out)} (figures in {args.out}/figures)")
    return 0


def _overlay(path: str | None, recording):
    """The overlay video writer for --overlay, or a no-op context."""
    import contextlib

    if not path:
        return contextlib.nullcontext()
    from wristtrack.report.overlay import OverlayWriter, nominal_fps

    layout = recording.hand.points if recording.hand is not None else None
    return OverlayWriter(path, recording.camera, layout, nominal_fps(recording))


def _report(args: argparse.Namespace) -> int:
    from wristtrack.report.html import write_report

    path = write_report(args.run_dir)
    print(f"wrote {path} (figures in {path.parent / 'figures'})")
    return 0


def _export_one(run_dir: str, fmt: str, out: str | None, units: str) -> None:
    from wristtrack.analysis.export import export_run, timing_warning

    path, traj = export_run(run_dir, fmt, out, units)
    warning = timing_warning(traj)
    if warning:
        print(warning, file=sys.stderr)
    print(f"wrote {path} ({len(traj.names)} markers, {int(traj.valid.sum())} of "
          f"{len(traj.times)} frames with an estimate, {traj.rate:.6g} Hz, {units})")


def _export(args: argparse.Namespace) -> int:
    _export_one(args.run_dir, args.format, args.out, args.units)
    return 0


def _label(args: argparse.Namespace) -> int:
    from wristtrack.camera import Camera
    from wristtrack.hand import MARKER_NAMES, HandLayout
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.label import check_labels, label_interactively

    camera = Camera.load(args.camera) if args.camera else None
    hand = HandLayout.load(args.hand) if args.hand else None
    with open_recording(args.input, camera=camera, hand=hand) as recording:
        if not args.check:
            label_interactively(recording, args.labels, args.frame, args.preview)
            return 0
        manual, labels, fit = check_labels(recording, args.labels)
    blobs = {int(k): b for b, k in enumerate(labels) if k >= 0}
    print(f"{args.labels}: frame {manual.frame}: "
          + ", ".join(f"{n} = blob {blobs[k]}" for k, n in enumerate(MARKER_NAMES))
          + f"; initial pose fits with {fit.rms_px:.2f} px RMS")
    return 0


def _batch(args: argparse.Namespace) -> int:
    from wristtrack.pipeline.batch import STUDY_CSV, STUDY_HTML, run_batch

    try:
        rows = run_batch(
            args.study_dir, args.out, _config(args), workers=args.workers, dask=args.dask,
            force=args.force, progress=not args.no_progress,
            checkpoint_every=args.checkpoint_every, smooth=args.smooth,
            report=not args.no_report,
        )
    except KeyboardInterrupt:
        print(f"wristtrack batch: interrupted; {args.out}/{STUDY_CSV} lists what finished; run "
              "the same command again to continue", file=sys.stderr)
        return 130
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "failed")}
    print(f"{counts['ok']} tracked, {counts['skipped']} already done, {counts['failed']} "
          f"failed; wrote {args.out}/{STUDY_CSV} and {args.out}/{STUDY_HTML}")
    return 1 if counts["failed"] else 0


def _evaluate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from wristtrack.analysis.evaluate import evaluate, format_report
    from wristtrack.io.atomic import write_json_atomic

    run = Path(args.run_dir)
    truth = Path(args.truth) if args.truth else None
    if truth is None:
        raise WristtrackError("give the ground truth with --truth truth.csv")
    result = evaluate(run / "poses.csv", truth)
    write_json_atomic(run / "evaluation.json", result)
    print(format_report(result))
    print(f"saved {run / 'evaluation.json'}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    from wristtrack.analysis.compare import compare, format_comparison
    from wristtrack.report.comparison import write_comparison

    result = compare(args.run_dir, args.reference, markers=args.markers, cluster=args.cluster,
                     fit_ratio=not args.no_clock_ratio, max_lag_s=args.max_lag,
                     time_offset_s=args.time_offset)
    json_path, html_path = write_comparison(args.out, result)
    print(format_comparison(result.result))
    print(f"wrote {json_path} and {html_path}")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from wristtrack.sim.realism import EFFECTS, PRESET_REAL
    from wristtrack.sim.render import render_recording

    effects = set(PRESET_REAL if args.preset == "real" else ())
    effects |= {e for e in EFFECTS if getattr(args, e, False)}
    if args.motion or args.cluster:
        return _simulate_recorded(args, sorted(effects))
    options = {"effects": sorted(effects), "hand_side": args.hand_side}
    if args.n_frames is not None:
        options["n_frames"] = args.n_frames
    out = render_recording(args.out, args.scenario, seed=args.seed, overwrite=args.overwrite,
                           **options)
    side = "" if args.hand_side == "right" else f", {args.hand_side} hand"
    print(f"wrote simulated recording {out} (ground truth in {out}/truth.csv; effects: "
          f"{', '.join(sorted(effects)) or 'none'}{side})")
    return 0


def _simulate_recorded(args: argparse.Namespace, effects: list[str]) -> int:
    from wristtrack.sim.recorded import ReferenceSettings, render_recorded

    if not (args.motion and args.cluster):
        raise WristtrackError("--motion FILE and --cluster A,B,C go together")
    reference = ReferenceSettings(
        rate_hz=args.reference_rate, offset_s=args.reference_offset,
        ratio=args.reference_clock_ratio, noise_mm=args.reference_noise,
    )
    out = render_recorded(
        args.out, args.motion, [s.strip() for s in args.cluster.split(",") if s.strip()],
        seed=args.seed, overwrite=args.overwrite, fps=args.fps, start_s=args.motion_start,
        duration_s=args.motion_duration, speed=args.speed, position_scale=args.position_scale,
        rotation_scale=args.rotation_scale, reference=reference, effects=tuple(effects),
        hand_side=args.hand_side,
    )
    print(f"wrote simulated recording {out} of {args.motion} (ground truth in {out}/truth.csv; "
          f"the motion-capture reference in {out}/reference.c3d, planted values in "
          f"{out}/reference.json)")
    return 0


# One switch per simulator effect (wristtrack.sim.realism.EFFECTS; left_hand is --hand-side).
_SIM_EFFECT_HELP = {
    "nonplanar": "arched palm: knuckles up to 7 mm above, thumb base 4.5 mm below the wrist "
    "marker's plane (3-D hand.json)",
    "soft_tissue": "fingers flex 0-70 deg; the MCP markers slide with the skin (3 mm at 90 deg)",
    "distortion": "a real Xtion's lens distortion (k1 0.033, k2 -0.108), in camera.json",
    "white_balance": "auto white balance drifting +-10 %% in red and blue",
    "auto_exposure": "auto-exposure steps of up to +-30 %% every 1.5-4 s",
    "jpeg": "colour JPEG-compressed at quality 80",
    "h264": "colour H.264-compressed (libx264, CRF 23; needs the video extra: PyAV)",
    "bayer": "Bayer mosaic and bilinear demosaicing",
    "shutter": "1/30 s shutter (motion blur)",
    "specular": "glossy domed markers with the lamp's highlight",
    "structured_light": "Kinect v1/Xtion depth: Nguyen noise, 1/8 px disparity steps, edge "
    "holes, invalid border, 1-2 px colour-depth misregistration",
}


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} is not a whole number >= 1")
    return value


class _Version(argparse.Action):
    """``--version``: the version and which tracker step runs (compiled or the generic path);
    numba is loaded only when this is asked for."""

    def __init__(self, option_strings, dest, **_):
        super().__init__(option_strings, dest, nargs=0,
                         help="show the version and which tracker step runs, then exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from wristtrack.tracking.compiled import describe

        print(f"wristtrack {__version__}\ntracker step: {describe()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wristtrack",
        description="6-DoF wrist pose from one RGB-D camera and six blue markers on the hand.",
    )
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser(
        "demo", help="render a simulated recording, track it and score it against its truth"
    )
    demo.add_argument("--out", default="demo_out", help="folder for the recording and the run")
    demo.add_argument("--scenario", default="reach", help="simulated scenario to render")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--model", choices=sorted(MODELS), default="default")
    demo.add_argument("--association", choices=METHODS, default="gnn")
    demo.add_argument("--no-depth", action="store_true", help="do not use depth in updates")
    demo.add_argument("--no-smooth", action="store_true", help="report the filtered poses")
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    demo.set_defaults(handler=_demo)

    track = sub.add_parser("track", help="track a recording: poses.csv and summary.json")
    track.add_argument("input", nargs="?", help="recording folder, video file or ROS bag")
    track.add_argument("--out", required=True, help="output folder")
    track.add_argument("--camera", help="camera.json (required for a video or a live camera)")
    track.add_argument("--hand", help="hand.json (marker layout); else the recording's or depth")
    track.add_argument(
        "--live", metavar="SOURCE",
        help="track a live camera in real time: realsense[:SERIAL|:FILE.bag], "
        "openni[:URI|:FILE.oni], replay:RECORDING (a folder played as a camera) or an OpenCV "
        "camera index; Ctrl-C ends the session",
    )
    track.add_argument("--view", action="store_true",
                       help="with --live: serve a live page (overlay video, angle traces, range "
                       "of motion) on 127.0.0.1")
    track.add_argument("--port", type=int, metavar="N",
                       help="port of the --view page (default 8765; 0 picks a free one)")
    track.add_argument("--record", metavar="DIR",
                       help="with --live: also write the raw frames as a recording folder")
    track.add_argument("--model", choices=sorted(MODELS), default="default")
    track.add_argument("--association", choices=METHODS, default="gnn")
    track.add_argument("--no-depth", action="store_true", help="do not use depth in updates")
    track.add_argument(
        "--smooth", action="store_true",
        help="offline unscented RTS smoothing of the whole run (filtered poses kept in "
        "poses_filtered.csv)",
    )
    track.add_argument("--color-topic", help="ROS bag colour topic (auto-detected otherwise)")
    track.add_argument("--depth-topic", help="ROS bag registered depth topic")
    track.add_argument("--info-topic", help="ROS bag camera_info topic")
    track.add_argument("--no-progress", action="store_true", help="no progress bar")
    track.add_argument("--resume", action="store_true",
                       help="continue an interrupted run in --out (same input and options)")
    track.add_argument("--checkpoint-every", type=_positive_int, default=300, metavar="N",
                       help="save a checkpoint for --resume every N frames (and every 30 s)")
    track.add_argument("--no-report", action="store_true",
                       help="do not write report.html and figures/ at the end")
    track.add_argument("--overlay", metavar="VIDEO.mp4",
                       help="also write the frames with blobs, labels and wrist axes drawn")
    track.add_argument("--labels", metavar="LABELS.json",
                       help="manual marker labels from 'wristtrack label' (when automatic "
                       "labelling refuses)")
    track.add_argument(
        "--export", action="append", choices=("c3d", "trc"),
        help="also write the marker trajectories as markers.c3d / markers.trc (repeatable)",
    )
    track.set_defaults(handler=_track)

    export = sub.add_parser("export", help="write a run's marker trajectories as C3D or TRC")
    export.add_argument("run_dir", help="output folder of 'wristtrack track'")
    export.add_argument("--format", required=True, choices=("c3d", "trc"))
    export.add_argument("--out", help="file to write (default RUN_DIR/markers.c3d or .trc)")
    export.add_argument("--units", choices=("mm", "m"), default="mm", help="coordinate units")
    export.set_defaults(handler=_export)

    label = sub.add_parser(
        "label", help="name the marker blobs of one frame by hand (when automatic labelling "
        "refuses); writes labels.json for 'track --labels'",
    )
    label.add_argument("input", help="recording folder, video file or ROS bag")
    label.add_argument("--frame", type=int, default=0, help="frame index to label (default 0)")
    label.add_argument("--labels", default="labels.json",
                       help="labels file to write, or to validate with --check")
    label.add_argument("--check", action="store_true",
                       help="validate LABELS against the recording instead of asking")
    label.add_argument("--preview", help="numbered-blob PNG (default LABELS_preview.png)")
    label.add_argument("--camera", help="camera.json (required for a video)")
    label.add_argument("--hand", help="hand.json (marker layout); else the recording's or depth")
    label.set_defaults(handler=_label)

    report = sub.add_parser("report", help="(re)write a run's report.html and figures/")
    report.add_argument("run_dir", help="output folder of 'wristtrack track'")
    report.set_defaults(handler=_report)

    batch = sub.add_parser(
        "batch", help="track every recording under a folder, in parallel; study.csv and .html"
    )
    batch.add_argument("study_dir", help="folder holding the recordings (searched recursively)")
    batch.add_argument("--out", required=True, help="output folder: one run folder each")
    batch.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                       help="local worker processes (default: one per CPU)")
    batch.add_argument("--dask", metavar="tcp://HOST:PORT",
                       help="run on this Dask cluster's workers instead (shared file system)")
    batch.add_argument("--force", action="store_true",
                       help="track again the recordings already done")
    batch.add_argument("--model", choices=sorted(MODELS), default="default")
    batch.add_argument("--association", choices=METHODS, default="gnn")
    batch.add_argument("--no-depth", action="store_true", help="do not use depth in updates")
    batch.add_argument("--checkpoint-every", type=_positive_int, default=300, metavar="N",
                       help="checkpoint each run every N frames, to resume it if interrupted")
    batch.add_argument("--smooth", action="store_true", help="smooth each run (see track)")
    batch.add_argument("--no-report", action="store_true",
                       help="no report.html per recording (study.csv/study.html still written)")
    batch.add_argument("--no-progress", action="store_true", help="no progress bar")
    batch.set_defaults(handler=_batch)

    evaluate = sub.add_parser("evaluate", help="score a run against a simulated truth.csv")
    evaluate.add_argument("run_dir", help="output folder of 'wristtrack track'")
    evaluate.add_argument("--truth", help="truth.csv of the simulated recording")
    evaluate.set_defaults(handler=_evaluate)

    comp = sub.add_parser(
        "compare", help="agreement of a run with a reference system (C3D, TRC, Qualisys TSV or "
        "a truth.csv): comparison.json and comparison.html",
    )
    comp.add_argument("run_dir", help="output folder of 'wristtrack track'")
    comp.add_argument("reference", help="reference recording: .c3d, .trc, .tsv or truth.csv")
    comp.add_argument("--out", required=True, help="folder for comparison.json and .html")
    comp.add_argument("--markers", metavar="WRIST=LABEL,...",
                      help="our markers' labels in the reference (three or more, or WRIST)")
    comp.add_argument("--cluster", metavar="A,B,C",
                      help="labels of a rigid cluster of 3+ markers on the back of the hand")
    comp.add_argument("--no-clock-ratio", action="store_true",
                      help="fit the time offset only (assume both clocks run at the same rate)")
    comp.add_argument("--max-lag", type=float, metavar="S",
                      help="search the time offset within +-S seconds only")
    comp.add_argument("--time-offset", type=float, metavar="S",
                      help="the clocks' offset when known (synchronised systems; needed for a "
                      "static trial): reference time = our time + S, not fitted")
    comp.set_defaults(handler=_compare)

    simulate = sub.add_parser("simulate", help="write a synthetic RGB-D recording with truth")
    simulate.add_argument("out", help="folder to create")
    simulate.add_argument("--scenario", default="deviation")
    simulate.add_argument("--seed", type=int, default=0)
    simulate.add_argument("--overwrite", action="store_true")
    simulate.add_argument("--n-frames", type=_positive_int, metavar="N",
                          help="render N frames (the scenario's movement squeezed into them)")
    simulate.add_argument("--preset", choices=("real",),
                          help="'real': every camera and hand effect at a real device's strength "
                          "(JPEG, not H.264)")
    simulate.add_argument("--hand-side", choices=("right", "left"), default="right",
                          help="left: the mirrored hand (CMC1 on -Y) and its hand.json")
    for name, text in _SIM_EFFECT_HELP.items():
        simulate.add_argument(f"--{name.replace('_', '-')}", dest=name, action="store_true",
                              help=text)
    rec = simulate.add_argument_group("recorded motion (instead of --scenario)")
    rec.add_argument("--motion", metavar="FILE",
                     help="drive the hand with a recorded cluster's motion (.c3d, .trc, .tsv)")
    rec.add_argument("--cluster", metavar="A,B,C", help="the cluster's marker labels in FILE")
    rec.add_argument("--motion-start", type=float, metavar="S",
                     help="segment start in FILE (default: its longest stretch without gaps)")
    rec.add_argument("--motion-duration", type=float, metavar="S", help="segment length")
    rec.add_argument("--speed", type=float, default=1.0,
                     help="play the motion this much faster (< 1: slower; stated in metadata)")
    rec.add_argument("--position-scale", type=float, default=1.0,
                     help="shrink the displacement (to stay in view)")
    rec.add_argument("--rotation-scale", type=float, default=1.0,
                     help="shrink the angular velocity")
    rec.add_argument("--fps", type=float, default=30.0, help="camera frame rate")
    rec.add_argument("--reference-rate", type=float, default=100.0, metavar="HZ",
                     help="the motion-capture system's rate")
    rec.add_argument("--reference-offset", type=float, default=0.4173, metavar="S",
                     help="planted clock offset (reference time = offset + ratio x camera time)")
    rec.add_argument("--reference-clock-ratio", type=float, default=1.0002, metavar="R")
    rec.add_argument("--reference-noise", type=float, default=0.05, metavar="MM",
                     help="marker noise of the reference, per coordinate")
    simulate.set_defaults(handler=_simulate)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except WristtrackError as exc:
        print(f"wristtrack {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"wristtrack {args.command}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # disk full, permissions: the system's own words, still one line
        print(f"wristtrack {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
