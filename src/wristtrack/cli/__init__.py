"""Command-line interface: ``wristtrack COMMAND ...``, one module per group of commands.

Errors the user can fix are printed as one line (no traceback) with a non-zero exit code.
"""

from __future__ import annotations

import argparse
import sys

from wristtrack import __version__
from wristtrack.cli import calibrate, runs, simulate, track
from wristtrack.errors import WristtrackError


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line, as the commands' own are: what is wrong and
    where the options are listed, not the whole usage first (the commands share it through
    add_subparsers, which makes its parsers of the parent's class)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (options: {self.prog} --help)\n")


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
    parser = _Parser(
        prog="wristtrack",
        description="6-DoF wrist pose from one RGB-D camera and six blue markers on the hand.",
    )
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", required=True)
    track.add_commands(sub)
    runs.add_commands(sub)
    simulate.add_commands(sub)
    calibrate.add_commands(sub)
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
