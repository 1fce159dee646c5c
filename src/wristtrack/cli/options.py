"""Options and argument types shared by several commands."""

from __future__ import annotations

import argparse

from wristtrack.filter.associate import METHODS
from wristtrack.tracking.config import SMOOTHING_NOISE
from wristtrack.tracking.models import MODELS


def _whole(text: str, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"{text} is not a whole number >= {minimum}")
    return value


def positive_int(text: str) -> int:
    return _whole(text, 1)


def non_negative_int(text: str) -> int:
    return _whole(text, 0)


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def finite_float(text: str) -> float:
    value = _number(text)
    if not abs(value) < float("inf"):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number")
    return value


def positive_float(text: str) -> float:
    value = _number(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number > 0")
    return value


def finite_non_negative(text: str) -> float:
    value = _number(text)
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number >= 0")
    return value


def non_negative_float(text: str) -> float:
    value = _number(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"{text} is not a number >= 0 (inf: no bound)")
    return value


def add_tracker_options(parser: argparse.ArgumentParser) -> None:
    """--model, --association, --no-depth, --no-skin-depth, --[no-]follow-slide,
    --[no-]follow-offset, --fixed-noise, --[no-]prime-noise, --smooth-noise and --coast-limit,
    read back by :func:`tracker_config`."""
    parser.add_argument("--model", choices=sorted(MODELS), default="default")
    parser.add_argument("--association", choices=METHODS, default="gnn")
    parser.add_argument("--no-depth", action="store_true", help="do not use depth in updates")
    parser.add_argument(
        "--no-skin-depth", action="store_true",
        help="use the markers' depth only, not the skin between them (e.g. a gloved or bandaged "
             "hand whose surface moves against the markers)")
    parser.add_argument(
        "--follow-slide", action=argparse.BooleanOptionalAction, default=True,
        help="carry the skin's slide over the knuckles in the filter state (the default); "
             "--no-follow-slide takes it as noise the markers share afresh each frame "
             "instead")
    parser.add_argument(
        "--follow-offset", action=argparse.BooleanOptionalAction, default=False,
        help="carry the depth map's offset from the colour image (a calibration error of 1-2 "
             "px) in the filter state, with the skin's slide; better positions from a "
             "structured-light camera, but see the README before using it for angles (the "
             "default, --no-follow-offset, takes it as noise the depths share afresh each "
             "frame)")
    parser.add_argument(
        "--fixed-noise", action="store_true",
        help="take the blobs' pixel noise and the skin slide as the model gives them instead of "
             "learning them from the recording (every recording weighed alike; summary.json "
             "says what was learned otherwise)")
    parser.add_argument(
        "--prime-noise", action=argparse.BooleanOptionalAction, default=True,
        help="start a recording's run from the noise a first pass over its first 10 s learns "
             "(the default; a live camera cannot: it learns from its first frame on); "
             "--no-prime-noise learns from the first frame on offline too, as a live run "
             "does")
    parser.add_argument(
        "--smooth-noise", choices=SMOOTHING_NOISE, default="model",
        help="with smoothing: smooth the run at the model's process noise (model, the "
             "default), or track the recording once more at the angular process noise its "
             "smoothed rates show and smooth that run (learned: one more pass; better for slow, "
             "smooth movements seen by a noisy camera, worse for fast ones; see the README)")
    parser.add_argument(
        "--coast-limit", nargs=2, type=non_negative_float, metavar=("DEG", "MM"),
        default=None,
        help="a frame with too few markers reports the predicted pose only while that adds at "
             "most DEG degrees and MM mm (1 sigma) to the last measured frame's uncertainty, "
             "else no pose (status lost) while the track waits for the markers (default 2 10; "
             "inf inf reports every prediction)")


def tracker_config(args: argparse.Namespace):
    """The TrackerConfig the options of :func:`add_tracker_options` ask for."""
    from wristtrack.tracking.surface import SurfaceSettings
    from wristtrack.tracking.tracker import TrackerConfig

    limit = {} if args.coast_limit is None else dict(
        coast_rot_sigma_deg=args.coast_limit[0], coast_pos_sigma_mm=args.coast_limit[1])
    if args.model in ("paper", "paper_rpy"):
        return TrackerConfig.paper(model=args.model, **limit)
    return TrackerConfig(association=args.association, use_depth=not args.no_depth,
                         surface=None if args.no_skin_depth else SurfaceSettings(),
                         adapt_slide=not args.fixed_noise, adapt_pixel=not args.fixed_noise,
                         follow_slide=args.follow_slide, follow_offset=args.follow_offset,
                         prime_noise=args.prime_noise, smoothing_noise=args.smooth_noise,
                         **limit)


