"""Batch throughput: the same study tracked by ``wristtrack batch`` with 1 and with N workers.

``python -m benchmarks.batch`` renders a small study once (simulated recordings of the
rotation scenarios) and times ``run_batch`` over it with each worker count, forcing every run,
from pool start to the last study.csv row: worker start-up is part of the cost a user pays.
The issue's target is a throughput with 2 workers of at least 1.7x one worker on a 2-core
machine. Run it on an otherwise idle machine: the figure is meaningless when other processes
use the cores (the result records the load average before and after).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from wristtrack.pipeline.batch import run_batch
from wristtrack.sim.render import render_recording

SCENARIOS = ("deviation", "flexion", "pronation")


def render_study(folder: str | Path, n_recordings: int = 6, n_frames: int = 120) -> Path:
    """``n_recordings`` simulated recordings of ``n_frames`` frames each under ``folder``, at
    10 fps: the movement then lasts n_frames / 10 s, slow enough to be tracked throughout (a
    benchmark of runs that lose the hand would time re-initialisation instead)."""
    folder = Path(folder)
    for i in range(n_recordings):
        scenario = SCENARIOS[i % len(SCENARIOS)]
        target = folder / f"s{i:02d}_{scenario}"
        if not (target / "truth.csv").is_file():  # rendered already (a re-used folder)
            render_recording(target, scenario, seed=i, n_frames=n_frames, fps=10.0,
                             overwrite=True)
    return folder


def bench_batch(
    workers: tuple[int, ...] = (1, 2),
    n_recordings: int = 6,
    n_frames: int = 120,
    folder: str | Path | None = None,
) -> dict[str, Any]:
    """Wall time of the batch with each worker count, recordings per second and the throughput
    ratio to the first count (``speedup``). ``folder`` keeps the rendered study for re-use."""
    with tempfile.TemporaryDirectory(prefix="wristtrack-bench-batch-") as tmp:
        study = render_study(Path(folder or tmp) / "study", n_recordings, n_frames)
        load_before = os.getloadavg()[0]
        seconds: dict[int, float] = {}
        for n in workers:
            out = Path(tmp) / f"out_{n}"
            start = time.perf_counter()
            rows = run_batch(study, out, workers=n, force=True, progress=False, echo=None)
            seconds[n] = time.perf_counter() - start
            failed = [r["recording"] for r in rows if r["status"] != "ok"]
            if failed:
                raise RuntimeError(f"benchmark recordings failed to track: {', '.join(failed)}")
        load_after = os.getloadavg()[0]
    base = workers[0]
    return {
        "recordings": n_recordings,
        "frames_each": n_frames,
        "cpu_count": os.cpu_count(),
        "seconds": seconds,
        "recordings_per_s": {n: n_recordings / s for n, s in seconds.items()},
        "speedup": {n: seconds[base] / s for n, s in seconds.items()},
        "load_average_before": load_before,
        "load_average_after": load_after,
    }


def format_result(result: dict[str, Any]) -> str:
    lines = [f"batch of {result['recordings']} recordings x {result['frames_each']} frames, "
             f"{result['cpu_count']} CPUs (load average {result['load_average_before']:.1f} "
             f"before, {result['load_average_after']:.1f} after)"]
    for n, s in result["seconds"].items():
        lines.append(f"  {n} worker(s): {s:6.1f} s, {result['recordings_per_s'][n]:.3f} "
                     f"recordings/s, {result['speedup'][n]:.2f}x")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--recordings", type=int, default=6)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--folder", help="keep the rendered study here (re-used next time)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args(argv)
    result = bench_batch(tuple(args.workers), args.recordings, args.frames, args.folder)
    print(json.dumps(result, indent=2) if args.json else format_result(result))


if __name__ == "__main__":
    main()
