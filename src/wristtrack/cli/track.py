"""Commands that track: demo, track (a recording or a live camera), label, batch."""

from __future__ import annotations

import argparse
import sys

from wristtrack.cli.options import add_tracker_options, positive_int, tracker_config
from wristtrack.cli.runs import export_one
from wristtrack.detect.config import PRESETS, detector_config
from wristtrack.errors import WristtrackError


def _demo(args: argparse.Namespace) -> int:
    from wristtrack.pipeline.demo import run_demo

    run_demo(args.out, args.scenario, args.seed, tracker_config(args),
             progress=not args.no_progress, smooth=not args.no_smooth)
    return 0


def _track(args: argparse.Namespace) -> int:
    detector_config(args.detector)  # an unknown name: one line listing the choices
    if args.live is not None:
        return _track_live(args)
    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.open import open_recording
    from wristtrack.io.run_folder import SURVEYED_HAND
    from wristtrack.pipeline.surveyed import is_surveyed
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
                recording, args.out, tracker_config(args), progress=not args.no_progress,
                smooth=args.smooth, overlay=overlay, resume=args.resume,
                checkpoint_every=args.checkpoint_every, labels=labels, detector=args.detector,
                survey=not args.no_survey,
            )
    except RunComplete as done:
        print(f"wristtrack track: {done}")
        return 0
    except KeyboardInterrupt:
        print(f"wristtrack track: interrupted; {args.out} keeps every frame done so far; run "
              "the same command with --resume to continue", file=sys.stderr)
        return 130
    frames = summary["frames"]
    no_depth = summary.get("frames_without_depth") or []
    print(f"tracked {frames['tracked']} of {frames['total']} frames"
          + (f" ({len(no_depth)} without depth, on colour alone)" if no_depth else "")
          + f"; wrote {args.out}/poses.csv and {args.out}/summary.json")
    if is_surveyed(summary["settings"]):
        print(f"  hand layout surveyed over the recording: {args.out}/{SURVEYED_HAND} (use it "
              "as --hand for this subject's other recordings)")
    for axis, rom in summary["range_of_motion"].items():
        if rom["range_deg"] is not None:
            print(f"  {axis:<10} {rom['min_deg']:7.1f} .. {rom['max_deg']:6.1f} deg "
                  f"(range {rom['range_deg']:.1f})")
    if summary.get("kinematics"):
        from wristtrack.analysis.kinematics import format_reaches

        print(format_reaches(summary["kinematics"]))
    return _write_outputs(args)


def _track_live(args: argparse.Namespace) -> int:
    """``track --live SOURCE``: real time (pipeline.live), with the live page and recording."""
    import contextlib

    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.live.sources import open_live
    from wristtrack.pipeline.live.loop import track_live

    if args.input:
        raise WristtrackError(f"give a recording ({args.input}) or --live SOURCE, not both")
    refused = [flag for flag, on in (("--resume", args.resume), ("--smooth", args.smooth),
                                     ("--labels", args.labels),
                                     ("--detector paper", args.detector != "default")) if on]
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
            from wristtrack.pipeline.live.view import DEFAULT_PORT, LiveView

            layout = source.hand.points if source.hand is not None else None
            port = DEFAULT_PORT if args.port is None else args.port
            view = stack.enter_context(LiveView(source.camera, layout, port, str(source.source)))
            print(f"live view: {view.url} (Ctrl-C ends the session)", flush=True)
        summary, live = track_live(source, args.out, tracker_config(args), record=args.record,
                                   view=view, overlay=overlay)
    if live.get("source_error"):
        print(f"wristtrack track: the camera stopped: {live['source_error']}", file=sys.stderr)
    frames, lat = live["frames"], live["latency_ms"]
    no_depth = (f", {frames['without_depth']} without depth, on colour alone"
                if frames["without_depth"] else "")
    print(f"tracked {summary['frames']['tracked']} of {frames['total']} frames "
          f"({frames['dropped']} dropped{no_depth}); latency p50 {lat['p50']:.1f} ms, p95 "
          f"{lat['p95']:.1f} ms; wrote {args.out}/poses.csv, summary.json and live.json")
    if summary.get("hand_layout_surveyed"):
        from wristtrack.io.run_folder import SURVEYED_HAND

        print(f"  hand layout surveyed over the session: {args.out}/{SURVEYED_HAND} (use it "
              "as --hand for this subject's next session)")
    if live.get("record"):
        rec = live["record"]
        print(f"recorded {rec['frames']} frames to {rec['folder']}"
              + (f" ({rec['lost']} lost: {rec['error'] or 'the disk fell behind'})"
                 if rec["lost"] else ""))
    return _write_outputs(args)


def _write_outputs(args: argparse.Namespace) -> int:
    """The exports, the overlay's line and the report of a finished run. Last, because they
    read the run folder's final poses.csv (smoothed, if asked for)."""
    for fmt in dict.fromkeys(args.export or ()):
        export_one(args.out, fmt, None, "mm")
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
            args.study_dir, args.out, tracker_config(args), workers=args.workers, dask=args.dask,
            force=args.force, progress=not args.no_progress,
            checkpoint_every=args.checkpoint_every, smooth=args.smooth,
            report=not args.no_report, survey=not args.no_survey,
        )
    except KeyboardInterrupt:
        print(f"wristtrack batch: interrupted; {args.out}/{STUDY_CSV} lists what finished; run "
              "the same command again to continue", file=sys.stderr)
        return 130
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "failed")}
    print(f"{counts['ok']} tracked, {counts['skipped']} already done, {counts['failed']} "
          f"failed; wrote {args.out}/{STUDY_CSV} and {args.out}/{STUDY_HTML}")
    return 1 if counts["failed"] else 0


def add_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register this module's commands on the top-level parser's subparsers."""
    demo = sub.add_parser(
        "demo", help="render a simulated recording, track it and score it against its truth"
    )
    demo.add_argument("--out", default="demo_out", help="folder for the recording and the run")
    demo.add_argument("--scenario", default="reach", help="simulated scenario to render")
    demo.add_argument("--seed", type=int, default=0)
    add_tracker_options(demo)
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
    add_tracker_options(track)
    track.add_argument(
        "--detector", default="default", metavar="{" + ",".join(PRESETS) + "}",
        help="marker detector: default (ours) or paper (the paper's section III-A as "
        "published, without our refinements: for comparison)",
    )
    track.add_argument(
        "--smooth", action="store_true",
        help="offline unscented RTS smoothing of the whole run (filtered poses kept in "
        "poses_filtered.csv; see --smooth-noise)",
    )
    track.add_argument(
        "--no-survey", action="store_true",
        help="without hand.json, track once with the layout of the still start instead of "
        "measuring it over the whole recording first (two passes; see hand_surveyed.json)",
    )
    track.add_argument("--color-topic", help="ROS bag colour topic (auto-detected otherwise)")
    track.add_argument("--depth-topic", help="ROS bag registered depth topic")
    track.add_argument("--info-topic", help="ROS bag camera_info topic")
    track.add_argument("--no-progress", action="store_true", help="no progress bar")
    track.add_argument("--resume", action="store_true",
                       help="continue an interrupted run in --out (same input and options)")
    track.add_argument("--checkpoint-every", type=positive_int, default=300, metavar="N",
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

    batch = sub.add_parser(
        "batch", help="track every recording under a folder, in parallel; study.csv and .html"
    )
    batch.add_argument("study_dir", help="folder holding the recordings (searched recursively)")
    batch.add_argument("--out", required=True, help="output folder: one run folder each")
    batch.add_argument("--workers", type=positive_int, default=None, metavar="N",
                       help="local worker processes (default: one per CPU)")
    batch.add_argument("--dask", metavar="tcp://HOST:PORT",
                       help="run on this Dask cluster's workers instead (shared file system)")
    batch.add_argument("--force", action="store_true",
                       help="track again the recordings already done")
    add_tracker_options(batch)
    batch.add_argument("--checkpoint-every", type=positive_int, default=300, metavar="N",
                       help="checkpoint each run every N frames, to resume it if interrupted")
    batch.add_argument("--smooth", action="store_true", help="smooth each run (see track)")
    batch.add_argument("--no-survey", action="store_true",
                       help="track each recording without hand.json once (see track)")
    batch.add_argument("--no-report", action="store_true",
                       help="no report.html per recording (study.csv/study.html still written)")
    batch.add_argument("--no-progress", action="store_true", help="no progress bar")
    batch.set_defaults(handler=_batch)

