"""``wristtrack simulate``: synthetic RGB-D recordings with ground truth, from a scripted
scenario or a recorded motion."""

from __future__ import annotations

import argparse

from wristtrack.cli.options import (
    finite_float,
    finite_non_negative,
    non_negative_int,
    positive_float,
    positive_int,
)
from wristtrack.errors import WristtrackError


def _simulate(args: argparse.Namespace) -> int:
    from wristtrack.sim.realism import EFFECTS, PRESET_REAL
    from wristtrack.sim.render import render_recording

    effects = set(PRESET_REAL if args.preset == "real" else ())
    effects |= {e for e in EFFECTS if getattr(args, e, False)}
    if args.motion or args.cluster:
        if args.scenario is not None or args.n_frames is not None:
            raise WristtrackError(
                "--scenario and --n-frames are for the scripted scenarios; a recorded motion "
                "(--motion) takes its segment from --motion-start and --motion-duration")
        return _simulate_recorded(args, sorted(effects))
    given = [f"--{name.replace('_', '-')}" for name in RECORDED_DEFAULTS
             if getattr(args, name) is not None]
    if given:
        raise WristtrackError(
            f"{', '.join(given)}: only for a recorded motion (--motion FILE --cluster A,B,C); "
            "a scripted scenario renders at 30 frames/s, its movement as scripted")
    options = {"effects": sorted(effects), "hand_side": args.hand_side}
    if args.n_frames is not None:
        options["n_frames"] = args.n_frames
    out = render_recording(args.out, args.scenario or DEFAULT_SCENARIO, seed=args.seed,
                           overwrite=args.overwrite, **options)
    side = "" if args.hand_side == "right" else f", {args.hand_side} hand"
    print(f"wrote simulated recording {out} (ground truth in {out}/truth.csv; effects: "
          f"{', '.join(sorted(effects)) or 'none'}{side})")
    return 0


def _simulate_recorded(args: argparse.Namespace, effects: list[str]) -> int:
    from wristtrack.sim.recorded import ReferenceSettings, render_recorded

    if not (args.motion and args.cluster):
        raise WristtrackError("--motion FILE and --cluster A,B,C go together")
    for name, default in RECORDED_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, default)
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


DEFAULT_SCENARIO = "deviation"
# The recorded motion's settings (None on the command line: not given) and their defaults
RECORDED_DEFAULTS = {
    "motion_start": None, "motion_duration": None, "speed": 1.0, "position_scale": 1.0,
    "rotation_scale": 1.0, "fps": 30.0, "reference_rate": 100.0, "reference_offset": 0.4173,
    "reference_clock_ratio": 1.0002, "reference_noise": 0.05,
}


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
    "depth_lag": "depth captured up to half a frame before or after the colour (streams on "
    "their own clocks), the delay in camera.json",
    "rolling_shutter": "a rolling-shutter colour sensor reading its rows over half to one frame "
    "interval, the readout in camera.json",
}


def add_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register this module's commands on the top-level parser's subparsers."""
    simulate = sub.add_parser("simulate", help="write a synthetic RGB-D recording with truth")
    simulate.add_argument("out", help="folder to create")
    simulate.add_argument("--scenario", help=f"scripted scenario (default {DEFAULT_SCENARIO})")
    simulate.add_argument("--seed", type=non_negative_int, default=0)
    simulate.add_argument("--overwrite", action="store_true")
    simulate.add_argument("--n-frames", type=positive_int, metavar="N",
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
    d = RECORDED_DEFAULTS
    rec.add_argument("--motion-start", type=finite_non_negative, metavar="S",
                     help="segment start in FILE (default: its longest stretch without gaps)")
    rec.add_argument("--motion-duration", type=positive_float, metavar="S",
                     help="segment length")
    rec.add_argument("--speed", type=positive_float,
                     help=f"play the motion this much faster (< 1: slower; stated in metadata; "
                     f"default {d['speed']})")
    rec.add_argument("--position-scale", type=positive_float,
                     help=f"shrink the displacement (to stay in view; default "
                     f"{d['position_scale']})")
    rec.add_argument("--rotation-scale", type=positive_float,
                     help=f"shrink the angular velocity (default {d['rotation_scale']})")
    rec.add_argument("--fps", type=positive_float,
                     help=f"camera frame rate (default {d['fps']})")
    rec.add_argument("--reference-rate", type=positive_float, metavar="HZ",
                     help=f"the motion-capture system's rate (default {d['reference_rate']})")
    rec.add_argument("--reference-offset", type=finite_float, metavar="S",
                     help="planted clock offset (reference time = offset + ratio x camera time; "
                     f"default {d['reference_offset']})")
    rec.add_argument("--reference-clock-ratio", type=positive_float, metavar="R",
                     help=f"default {d['reference_clock_ratio']}")
    rec.add_argument("--reference-noise", type=finite_non_negative, metavar="MM",
                     help="marker noise of the reference, per coordinate (default "
                     f"{d['reference_noise']})")
    simulate.set_defaults(handler=_simulate)
