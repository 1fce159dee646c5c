"""Command-line interface: ``wristtrack COMMAND ...``.

Errors the user can fix are printed as one line (no traceback) with a non-zero exit code.
"""

from __future__ import annotations

import argparse
import sys

from wristtrack import __version__
from wristtrack.associate import METHODS
from wristtrack.errors import WristtrackError
from wristtrack.motion import MODELS


def _demo(args: argparse.Namespace) -> int:
    from wristtrack.demo import run_demo

    run_demo(args.out, args.scenario, args.seed, _config(args), progress=not args.no_progress)
    return 0


def _config(args: argparse.Namespace):
    from wristtrack.tracker import TrackerConfig

    if args.model == "paper":
        return TrackerConfig.paper()
    return TrackerConfig(association=args.association, use_depth=not args.no_depth)


def _track(args: argparse.Namespace) -> int:
    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.recording import open_recording
    from wristtrack.pipeline import track_recording

    camera = Camera.load(args.camera) if args.camera else None
    hand = HandLayout.load(args.hand) if args.hand else None
    options = {
        k: v
        for k, v in (("color_topic", args.color_topic), ("depth_topic", args.depth_topic),
                     ("info_topic", args.info_topic))
        if v
    }
    source = f"live:{args.live}" if args.live is not None else args.input
    if source is None:
        raise WristtrackError("give a recording to track, or --live INDEX for a camera")
    with open_recording(source, camera=camera, hand=hand, **options) as recording:
        summary = track_recording(
            recording, args.out, _config(args), progress=not args.no_progress
        )
    frames = summary["frames"]
    print(f"tracked {frames['tracked']} of {frames['total']} frames; wrote {args.out}/poses.csv "
          f"and {args.out}/summary.json")
    for axis, rom in summary["range_of_motion"].items():
        if rom["range_deg"] is not None:
            print(f"  {axis:<10} {rom['min_deg']:7.1f} .. {rom['max_deg']:6.1f} deg "
                  f"(range {rom['range_deg']:.1f})")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from wristtrack.evaluate import evaluate, format_report
    from wristtrack.summary import write_json_atomic

    run = Path(args.run_dir)
    truth = Path(args.truth) if args.truth else None
    if truth is None:
        raise WristtrackError("give the ground truth with --truth truth.csv")
    result = evaluate(run / "poses.csv", truth)
    write_json_atomic(run / "evaluation.json", result)
    print(format_report(result))
    print(f"saved {run / 'evaluation.json'}")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from wristtrack.sim.render import render_recording

    out = render_recording(args.out, args.scenario, seed=args.seed, overwrite=args.overwrite)
    print(f"wrote simulated recording {out} (ground truth in {out}/truth.csv)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wristtrack",
        description="6-DoF wrist pose from one RGB-D camera and six blue markers on the hand.",
    )
    parser.add_argument("--version", action="version", version=f"wristtrack {__version__}")
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
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    demo.set_defaults(handler=_demo)

    track = sub.add_parser("track", help="track a recording: poses.csv and summary.json")
    track.add_argument("input", nargs="?", help="recording folder, video file or ROS bag")
    track.add_argument("--out", required=True, help="output folder")
    track.add_argument("--camera", help="camera.json (required for a video or a live camera)")
    track.add_argument("--hand", help="hand.json (marker layout); else the recording's or depth")
    track.add_argument("--live", type=int, metavar="INDEX", help="track a live camera")
    track.add_argument("--model", choices=sorted(MODELS), default="default")
    track.add_argument("--association", choices=METHODS, default="gnn")
    track.add_argument("--no-depth", action="store_true", help="do not use depth in updates")
    track.add_argument("--color-topic", help="ROS bag colour topic (auto-detected otherwise)")
    track.add_argument("--depth-topic", help="ROS bag registered depth topic")
    track.add_argument("--info-topic", help="ROS bag camera_info topic")
    track.add_argument("--no-progress", action="store_true", help="no progress bar")
    track.set_defaults(handler=_track)

    evaluate = sub.add_parser("evaluate", help="score a run against a simulated truth.csv")
    evaluate.add_argument("run_dir", help="output folder of 'wristtrack track'")
    evaluate.add_argument("--truth", help="truth.csv of the simulated recording")
    evaluate.set_defaults(handler=_evaluate)

    simulate = sub.add_parser("simulate", help="write a synthetic RGB-D recording with truth")
    simulate.add_argument("out", help="folder to create")
    simulate.add_argument("--scenario", default="deviation")
    simulate.add_argument("--seed", type=int, default=0)
    simulate.add_argument("--overwrite", action="store_true")
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


if __name__ == "__main__":
    sys.exit(main())
