"""Frames lost: accuracy when a slow machine or camera delivers only some of the frames.

Live, the newest frame wins (pipeline/live/loop.py): a tracker slower than the camera drops
frames, and the frames it takes come at uneven, sometimes long intervals; a slow camera delivers
evenly spaced frames at a low rate. Both are measured offline, on rendered 30 fps recordings
(the reach and the 'mix' movement) cut to a subset of their frames, tracked as ``track`` does
and scored against the truth:

- random cuts: the first frame and 4-15 others drawn at random (gaps up to seconds), as a run
  that dropped most frames;
- even cuts: every 4th, 7th and 10th frame (7.5, 4.3 and 3 fps);
- both again on the 'mix' movement with every camera and hand effect at its realistic strength
  (benchmarks.robustness' "all (preset real)", rendered afresh).

Per set: the frames reported as tracking, those more than GROSS_DEG off the truth on any wrist
angle (a wrong pose reported as right), and the angle error's 99th percentile and maximum. What
a user needs to trust a live run's rows is that none is grossly off: a frame the tracker cannot
explain should say so (coasting, lost), not report a pose.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.robustness import render_condition
from wristtrack.io.folder import FolderRecording
from wristtrack.io.poses import read_poses
from wristtrack.pipeline.track import track_recording
from wristtrack.sim.render import render_recording

RECORDINGS = ("reach", "no_hand")  # a fast reach; all three wrist axes ('mix')
REALISTIC = "all (preset real)"  # benchmarks.robustness' condition: every effect, real strengths
GROSS_DEG = 5.0
RANDOM_CUTS = 60  # per the whole set, alternating the recordings
STRIDES = (4, 7, 10)
ANGLES = ("deviation_deg", "flexion_deg", "pronation_deg")


def rendered(cache: Path, name: str, seed: int = 0) -> Path:
    """The recording at its natural length and 30 fps, rendered once into ``cache``."""
    folder = cache / f"{name}-{seed}"
    if not (folder / "truth.csv").exists():
        render_recording(folder, name, seed=seed, overwrite=True)
    return folder


def cut(folder: Path, frames, dest: Path, hand: bool = True, without_depth=()) -> Path:
    """``dest``: the recording ``folder`` holding only its frames ``frames`` (indices, in
    order): frames.csv those rows, its camera, images and hand.json linked, not copied;
    without hand.json where ``hand`` is False (as a camera SDK's file has none); the frames
    ``without_depth`` (indices of ``folder``) with an empty depth cell, as a camera that lost
    their depth would have recorded them. The truth files, which describe every frame, stay
    behind."""
    dest.mkdir(parents=True)
    for name in ("camera.json", "rgb", "depth") + (("hand.json",) if hand else ()):
        if (folder / name).exists():
            (dest / name).symlink_to((folder / name).resolve())
    lines = (folder / "frames.csv").read_text().splitlines()
    lost = {int(i) for i in without_depth}

    def row(i: int) -> str:
        line = lines[1 + i]
        return line.rsplit(",", 1)[0] + "," if i in lost else line

    (dest / "frames.csv").write_text("\n".join([lines[0], *(row(int(i)) for i in frames)])
                                     + "\n")
    return dest


def angle_errors(recording: Path, frames: np.ndarray, work: Path) -> np.ndarray:
    """(tracked frames, 3) wrist-angle errors (deg) of ``recording`` cut to ``frames``."""
    with FolderRecording(cut(recording, frames, work / "cut")) as rec:
        track_recording(rec, work / "run", progress=False)
    poses, truth = read_poses(work / "run" / "poses.csv"), read_poses(recording / "truth.csv")
    tracked = poses["status"] == "tracking"
    return np.column_stack([poses[a][tracked] - truth[a][frames[tracked]] for a in ANGLES])


def _random_frames(rng: np.random.Generator, n: int) -> np.ndarray:
    """The first of ``n`` frames and 4-15 others drawn at random, in order."""
    k = int(rng.integers(4, 16))
    return np.unique(np.concatenate(([0], rng.choice(np.arange(1, n), k, replace=False))))


def _stats(errors: list[np.ndarray]) -> dict[str, Any]:
    worst = np.abs(np.concatenate(errors)).max(axis=1) if errors else np.zeros(0)
    return {
        "tracked": int(worst.size),
        "gross": int(np.sum(worst > GROSS_DEG)),
        "p99_deg": float(np.percentile(worst, 99)) if worst.size else float("nan"),
        "max_deg": float(worst.max()) if worst.size else float("nan"),
    }


def bench_dropped(cache: Path | None = None, n_random: int = RANDOM_CUTS,
                  seed: int = 7) -> dict[str, Any]:
    """Random and even cuts of the rendered recordings, tracked and scored."""
    cache = Path(cache or Path(tempfile.gettempdir()) / "wristtrack-bench")
    recordings = {name: rendered(cache, name) for name in RECORDINGS}
    n_frames = {name: len((f / "frames.csv").read_text().splitlines()) - 1
                for name, f in recordings.items()}
    rng = np.random.default_rng(seed)
    sets: dict[str, list[np.ndarray]] = {"random": []}
    with tempfile.TemporaryDirectory(prefix="wristtrack-bench-dropped-") as tmp:
        for trial in range(n_random):
            name = RECORDINGS[trial % len(RECORDINGS)]
            n = n_frames[name]
            sets["random"].append(angle_errors(recordings[name], _random_frames(rng, n),
                                               Path(tmp) / f"random-{trial}"))
        for stride in STRIDES:
            key = f"every {stride}th frame ({30 / stride:.1f} fps)"
            sets[key] = [angle_errors(f, np.arange(0, n_frames[name], stride),
                                      Path(tmp) / f"{name}-{stride}")
                         for name, f in recordings.items()]
        real = render_condition(cache, REALISTIC, 0, None)
        n = len((real / "frames.csv").read_text().splitlines()) - 1
        rng = np.random.default_rng(seed + 1)
        key = "random, every effect (preset real)"
        sets[key] = [angle_errors(real, _random_frames(rng, n), Path(tmp) / f"real-random-{trial}")
                     for trial in range(n_random // 2)]
        sets["every 4th/7th/10th frame, every effect"] = [
            angle_errors(real, np.arange(0, n, stride), Path(tmp) / f"real-every-{stride}")
            for stride in STRIDES]
    return {"random_cuts": n_random, "sets": {k: _stats(v) for k, v in sets.items()}}


def dropped_section(result: dict[str, Any]) -> list[str]:
    """The BENCHMARKS.md section for :func:`bench_dropped`'s result."""
    lines = [
        "## Frames lost (a slow machine or camera)",
        "",
        f"The reach and the 'mix' movement (30 fps renders) cut to {result['random_cuts']} "
        "random subsets (the first frame and 4-15 others: gaps up to seconds, as a live run "
        "that dropped most frames) and to evenly spaced frames, tracked as `track` does; then "
        f"the 'mix' with every effect at realistic strength ({result['random_cuts'] // 2} "
        "random subsets, and the three even cuts together). "
        f"Gross: tracked frames more than {GROSS_DEG:.0f} deg off the truth on a wrist angle. "
        "Target: none.",
        "",
        "| frames taken | tracked | gross | worst angle error p99 (deg) | max (deg) |",
        "|---|---|---|---|---|",
    ]
    for name, s in result["sets"].items():
        lines.append(f"| {name} | {s['tracked']} | {s['gross']} | {s['p99_deg']:.2f} | "
                     f"{s['max_deg']:.1f} |")
    return [*lines, "", summary_line(result), ""]


def summary_line(result: dict[str, Any]) -> str:
    gross = sum(s["gross"] for s in result["sets"].values())
    tracked = sum(s["tracked"] for s in result["sets"].values())
    return (f"- Frames lost: {gross} of {tracked} tracked frames more than {GROSS_DEG:.0f} deg "
            f"off over random and even cuts ({'meets' if gross == 0 else '**misses**'} the "
            "target: none).")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, help="rendered recordings (re-used)")
    parser.add_argument("--random-cuts", type=int, default=RANDOM_CUTS)
    args = parser.parse_args(argv)
    print("\n".join(dropped_section(bench_dropped(args.cache, args.random_cuts))))


if __name__ == "__main__":
    main()
