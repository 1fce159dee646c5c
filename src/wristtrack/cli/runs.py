"""Commands on finished runs: report, export, evaluate, compare."""

from __future__ import annotations

import argparse
import sys

from wristtrack.cli.options import finite_float, positive_float
from wristtrack.errors import WristtrackError


def _report(args: argparse.Namespace) -> int:
    from wristtrack.report.html import write_report

    path = write_report(args.run_dir)
    print(f"wrote {path} (figures in {path.parent / 'figures'})")
    return 0


def export_one(run_dir: str, fmt: str, out: str | None, units: str) -> None:
    from wristtrack.analysis.export import export_run, timing_warning

    path, traj = export_run(run_dir, fmt, out, units)
    warning = timing_warning(traj)
    if warning:
        print(warning, file=sys.stderr)
    print(f"wrote {path} ({len(traj.names)} markers, {int(traj.valid.sum())} of "
          f"{len(traj.times)} frames with an estimate, {traj.rate:.6g} Hz, {units})")


def _export(args: argparse.Namespace) -> int:
    export_one(args.run_dir, args.format, args.out, args.units)
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from wristtrack.analysis.evaluate import evaluate, format_report
    from wristtrack.io.atomic import write_json_atomic
    from wristtrack.io.run_folder import run_file

    run = Path(args.run_dir)
    truth = Path(args.truth) if args.truth else None
    if truth is None:
        raise WristtrackError("give the ground truth with --truth truth.csv")
    result = evaluate(run_file(run, "poses.csv"), truth)
    write_json_atomic(run / "evaluation.json", result)
    print(format_report(result))
    print(f"saved {run / 'evaluation.json'}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    from wristtrack.analysis.compare.comparison import compare, format_comparison
    from wristtrack.report.comparison import write_comparison

    result = compare(args.run_dir, args.reference, markers=args.markers, cluster=args.cluster,
                     fit_ratio=not args.no_clock_ratio, max_lag_s=args.max_lag,
                     time_offset_s=args.time_offset, lowpass_hz=args.lowpass)
    json_path, html_path = write_comparison(args.out, result)
    print(format_comparison(result.result))
    print(f"wrote {json_path} and {html_path}")
    return 0


def add_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register this module's commands on the top-level parser's subparsers."""
    export = sub.add_parser("export", help="write a run's marker trajectories as C3D or TRC")
    export.add_argument("run_dir", help="output folder of 'wristtrack track'")
    export.add_argument("--format", required=True, choices=("c3d", "trc"))
    export.add_argument("--out", help="file to write (default RUN_DIR/markers.c3d or .trc)")
    export.add_argument("--units", choices=("mm", "m"), default="mm", help="coordinate units")
    export.set_defaults(handler=_export)

    report = sub.add_parser("report", help="(re)write a run's report.html and figures/")
    report.add_argument("run_dir", help="output folder of 'wristtrack track'")
    report.set_defaults(handler=_report)

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
    comp.add_argument("--max-lag", type=positive_float, metavar="S",
                      help="search the time offset within +-S seconds only")
    comp.add_argument("--time-offset", type=finite_float, metavar="S",
                      help="the clocks' offset when known (synchronised systems; needed for a "
                      "static trial): reference time = our time + S, not fitted")
    comp.add_argument("--lowpass", type=positive_float, metavar="HZ",
                      help="low-pass the reference's marker trajectories at HZ first, as labs "
                      "filter motion-capture data (4th-order zero-lag Butterworth; e.g. 10); "
                      "default: as recorded")
    comp.set_defaults(handler=_compare)

