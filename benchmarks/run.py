"""Benchmarks behind ``make bench``: accuracy against the peers and the physical limit on the
simulators, robustness to real cameras and hands, speed, live tracking, validation against a
reference system and the paper at its best.

Writes docs/BENCHMARKS.md: a summary and one section per benchmark, every figure measured by
this code. Speed is reported as ratios to the peer measured in the same run, since absolute
times on shared machines are noisy. ``--only NAME[,NAME]`` measures those sections again and
keeps the others as they were (each section says when, where and how it was measured).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import scipy

from benchmarks.document import body, compose, read_blocks
from wristtrack import __version__
from wristtrack.sim.detections import NoiseModel


@dataclass(frozen=True)
class Context:
    quick: bool
    seeds: tuple[int, ...]
    soak: bool
    cache: Path


Section = Callable[[Context, dict], tuple[list[str], list[str]]]  # -> (summary, body)


def _step(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.step import speed_summary, step_section, time_tracker_step

    step = time_tracker_step(n_frames=60 if ctx.quick else 300,
                             stonesoup_frames=10 if ctx.quick else 60)  # fmt: skip
    return [speed_summary(step)], step_section(step)


def _simulated(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.accuracy import accuracy_sections, summary_lines
    from benchmarks.simulated import accuracy_table, association_table

    compare = accuracy_sections(ctx.seeds, findings=f, max_frames=60 if ctx.quick else None)
    table = accuracy_table(ctx.seeds, f)
    association = association_table(ctx.seeds)
    summary = _simulated_summary(f) + summary_lines(f)
    return summary, [
        *compare,
        "## Accuracy on the measurement-level simulator",
        "",
        f"Acceptance setting: {NoiseModel().pixel_sigma:g} px blob noise (the filter's own pixel "
        "model; the realism is the rendered sections'), Poisson clutter of 3 blobs per frame, "
        "10% missed "
        "detections, MCP4 and MCP5 occluded for 10 frames mid-recording, Kinect-like depth noise "
        f"(1.425e-3 z^2 m). Camera-frame errors, mean over seeds {list(ctx.seeds)}.",
        "",
        *table,
        "",
        "## Association under clutter next to the markers",
        "",
        "With clutter spread uniformly over the image all three rules agree (table above). They "
        "differ when blue blobs sit right beside the markers: the same acceptance noise plus "
        "1.5 blobs per frame within ~8 px of random markers (at their depth +- 1 cm). The "
        "paper's rule lets a blob beside a marker claim it as well; the one-to-one rules do "
        "not. GNN is the default: one assignment per frame instead of JPDA's joint events.",
        "",
        *association,
        "",
    ]


def _simulated_summary(f: dict) -> list[str]:
    lines = [
        f"- Accuracy, measurement-level acceptance setting: the default tracker's worst "
        f"scenario is {f['sim_rot']:.2f} deg / {f['sim_pos']:.2f} mm (targets 1.5 deg / 3 mm), "
        f"{f['sim_labels']:.2%} of marker blobs labelled right; the paper's configuration is at "
        f"best {f['sim_paper_rot']:.1f} deg.",
    ]
    return lines


def _rendered(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.accuracy import ACCURACY_ROWS, lead_line, rendered_sections
    from benchmarks.pipeline import pipeline_sections, rendered_recordings

    n_frames = 40 if ctx.quick else None
    pipeline = pipeline_sections(
        ctx.cache, soak=ctx.soak, findings=f, n_frames=n_frames,
        lengths=(200, 500, 1_000) if ctx.quick else (1_000, 10_000, 50_000),
    )
    peers = rendered_sections(rendered_recordings(ctx.cache, n_frames=n_frames), findings=f)
    ours = {k for k, r in ACCURACY_ROWS.items() if r.ours}
    summary = [*_rendered_summary(f),
               lead_line(f["rendered_accuracy"], ours, "rendered RGB-D recordings")]
    return summary, [*pipeline, *peers]


def _rendered_summary(f: dict) -> list[str]:
    lines: list[str] = []
    if "render_rot" in f:
        lines.append(
            f"- Rendered RGB-D recordings (detector + tracker): worst default scenario "
            f"{f['render_rot']:.2f} deg / {f['render_pos']:.2f} mm (targets 2 deg / 5 mm); "
            f"worst range-of-motion error {f['render_rom']:.2f} deg (target 2 deg): "
            + ("met." if f["render_rom"] <= 2.0 else "**not met** by the causal filter: the "
               "error is the noise peak-to-peak of axes that do not move.")
        )
    if "render_rot_smooth" in f:
        lines.append(
            f"- With `track --smooth` (offline unscented RTS smoother): worst scenario "
            f"{f['render_rot_smooth']:.2f} deg / {f['render_pos_smooth']:.2f} mm, worst "
            f"range-of-motion error {f['render_rom_smooth']:.2f} deg (target 2 deg: "
            + ("met" if f["render_rom_smooth"] <= 2.0 else "**not met**")
            + "); orientation RMSE lower than the filter's on "
            + ("every scenario." if f.get("render_smooth_better") else "**not** every scenario.")
        )
    if "detect_ms" in f:
        tp = [f["throughput"], f.get("throughput_mp4", np.nan)]
        met = all(x >= 0.5 for x in tp)
        lines.append(
            f"- Detection {f['detect_ms']:.2f} ms per frame as `track` runs it (target 2 ms: "
            + ("met" if f["detect_ms"] <= 2.0 else "**not met**")
            + f"); `track` runs at {tp[0]:.0%} of decode-only throughput on PNGs and "
            f"{tp[1]:.0%} on MP4 (target 50%: " + ("met" if met else "**not met**") + ")."
        )
    if f.get("reach_metrics"):
        parts = [f"{label}: peak speed {e:+.1f}%, movement time {m:+.1f} frames"
                 for label, (e, m) in f["reach_metrics"].items()]
        met = all(abs(e) <= 5 and abs(m) <= 2 for e, m in f["reach_metrics"].values())
        lines.append("- Reach metrics on the rendered reach against truth (targets 5%, 2 frames: "
                     + ("met" if met else "**not met**") + "): " + "; ".join(parts) + ".")
    if f.get("scaling"):
        rows = f["scaling"]
        ms = [1e3 * s / n for n, s, _ in rows]
        rss = [r for _, _, r in rows]
        lines.append(
            f"- Long recordings: from {rows[0][0]:,} to {rows[-1][0]:,} frames, time per frame "
            f"goes {ms[0]:.2f} -> {ms[-1]:.2f} ms and peak memory {rss[0]:.0f} -> {rss[-1]:.0f} "
            "MiB (" + ("flat" if rss[-1] <= 1.1 * rss[0] + 5 and ms[-1] <= 1.3 * ms[0]
                       else "**grows**") + ")."
        )
    return lines


def _robustness(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.robustness import robustness_sections, summary_lines

    section = robustness_sections(ctx.cache, ctx.seeds, n_frames=60 if ctx.quick else None,
                                  findings=f)
    return summary_lines(f["robustness"]), section


def _still_reach(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.still_reach import still_reach_section

    return still_reach_section(ctx.cache, ctx.seeds[:1] if ctx.quick else ctx.seeds)


def _spread(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.seed_spread import SPREAD_SEEDS, seed_spread, spread_section

    seeds = tuple(range(2 if ctx.quick else max(SPREAD_SEEDS, len(ctx.seeds))))
    result = seed_spread(ctx.cache, seeds, n_frames=60 if ctx.quick else None)
    return spread_section(result, seeds, table_seeds=len(ctx.seeds))


def _budget(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.error_budget import error_budget, error_budget_section, summary_lines
    from benchmarks.seed_spread import SPREAD_SEEDS

    seeds = tuple(range(2 if ctx.quick else max(SPREAD_SEEDS, len(ctx.seeds))))
    result = error_budget(ctx.cache, seeds, ctx.seeds, n_frames=60 if ctx.quick else None)
    return summary_lines(result), error_budget_section(result, seeds, ctx.seeds)


def _batch(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    section = _batch_section(f, ctx.quick)
    lines: list[str] = []
    if f.get("batch") and 2 in f["batch"]["speedup"]:
        x = f["batch"]["speedup"][2]
        lines.append(
            f"- Batch: 2 workers give {x:.2f}x the throughput of one (target 1.7x: "
            + ("met" if x >= 1.7 else "**not met**") + "; one worker already decodes its "
            "frames on the second core)."
        )
    return lines, section


def _live(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.live import SCENARIOS, bench_live, live_section, summary_line

    result = bench_live(ctx.cache, ("reach",) if ctx.quick else SCENARIOS)
    return [summary_line(result)], live_section(result)


def _dropped(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.dropped import bench_dropped, dropped_section, summary_line

    result = bench_dropped(ctx.cache, n_random=10 if ctx.quick else 60)
    return [summary_line(result)], dropped_section(result)


def _validation(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.validation import validation_section

    section = validation_section(ctx.cache, ctx.quick, f)
    return [f"- {line}" for line in f.get("validation_summary", [])], section


def _paper(ctx: Context, f: dict) -> tuple[list[str], list[str]]:
    from benchmarks.paper_baseline import paper_baseline_section

    return [], paper_baseline_section(ctx.quick, f, ctx.cache)


SECTIONS: dict[str, Section] = {  # in the document's order
    "step": _step,
    "simulated": _simulated,
    "rendered": _rendered,
    "robustness": _robustness,
    "still_reach": _still_reach,
    "spread": _spread,
    "budget": _budget,
    "batch": _batch,
    "live": _live,
    "dropped": _dropped,
    "validation": _validation,
    "paper": _paper,
}


def _batch_section(findings: dict, quick: bool) -> list[str]:
    """`wristtrack batch` on one rendered study with 1 and 2 workers (bench_batch)."""
    from benchmarks.batch import bench_batch

    result = bench_batch(n_recordings=2 if quick else 6, n_frames=30 if quick else 300)
    findings["batch"] = result
    lines = [
        "## Batch throughput (`wristtrack batch`, process pool)",
        "",
        f"{result['recordings']} rendered recordings of {result['frames_each']} frames each, "
        "tracked and reported by `run_batch` with each worker count (pool start-up included), "
        f"on {result['cpu_count']} CPUs; load average {result['load_average_before']:.1f} before "
        f"and {result['load_average_after']:.1f} after. Target: 2 workers >= 1.7x one. "
        "One worker is not one core: it decodes the next frames in a thread while it tracks "
        "(`io/prefetch.py`), so a second worker only has the rest of the second core to take "
        "(at d18eb24, before the read-ahead: one worker 45.4 s, two 21.9 s, 2.07x).",
        "",
        "| workers | seconds | recordings/s | throughput vs 1 worker |",
        "|---|---|---|---|",
    ]
    for n, seconds in result["seconds"].items():
        lines.append(f"| {n} | {seconds:.1f} | {result['recordings_per_s'][n]:.3f} | "
                     f"{result['speedup'][n]:.2f}x |")
    return [*lines, ""]


def _stonesoup_version() -> str:
    try:
        import stonesoup
    except ImportError:
        return "not installed"
    return stonesoup.__version__


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True, cwd=Path(__file__).parent)
        # the code measured: docs/ (this very file) does not count
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                                "src", "benchmarks"],
                               capture_output=True, text=True, check=True,
                               cwd=Path(__file__).parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown commit"
    return out.stdout.strip() + (" with uncommitted changes" if dirty else "")


def _provenance(name: str, command: str, seconds: float) -> str:
    return (f"_Measured by `{command}` on {time.strftime('%Y-%m-%d')}, wristtrack {__version__} "
            f"at {_commit()}, {_cpu()} ({os.cpu_count()} cores), in {seconds / 60:.1f} min._")


def _intro() -> list[str]:
    import filterpy

    return [
        "# Benchmarks",
        "",
        "Written by `make bench` (`python -m benchmarks.run`); `python -m benchmarks.run --only "
        "NAME[,NAME]` measures sections again (" + ", ".join(SECTIONS) + ") and keeps the "
        "others. Each section says when, at which commit and by which command it was measured.",
        f"Software of the last run: Python {platform.python_version()}, NumPy {np.__version__}, "
        f"SciPy {scipy.__version__}, OpenCV {cv2.__version__}, FilterPy {filterpy.__version__}, "
        f"Stone Soup {_stonesoup_version()}; {platform.platform()}. Shared machine: compare "
        "ratios measured in the same run, not absolute times.",
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/BENCHMARKS.md"))
    parser.add_argument("--seeds", type=int, default=3, help="Monte Carlo seeds per scenario")
    parser.add_argument(
        "--no-soak", action="store_true", help="skip the scaling run (1k, 10k, 50k frames)"
    )
    parser.add_argument(
        "--quick", action="store_true",
        help="reduced sizes to check the code works (1 seed, 60 frames per simulated run, "
        "40-frame renders, short scaling run); its figures are not the benchmark's",
    )
    parser.add_argument(
        "--only", type=lambda s: s.split(","), default=list(SECTIONS), metavar="NAME[,NAME]",
        help="measure these sections again and keep the others in --out: "
        + ", ".join(SECTIONS),
    )
    parser.add_argument("--print", action="store_true",
                        help="print the sections measured instead of writing --out")
    parser.add_argument("--keep-renders", action="store_true",
                        help="keep the rendered recordings in the render cache afterwards "
                        "(~14 GB for a full run; every run renders afresh)")
    args = parser.parse_args(argv)
    unknown = [n for n in args.only if n not in SECTIONS]
    if unknown:
        parser.error(f"unknown section {', '.join(unknown)}: choose from {', '.join(SECTIONS)}")
    ctx = Context(quick=args.quick, seeds=(0,) if args.quick else tuple(range(args.seeds)),
                  soak=not args.no_soak, cache=Path(tempfile.gettempdir()) / "wristtrack-bench")
    with _cache_lock(ctx.cache) as mine:
        if not mine:
            print(f"error: another benchmark run is using {ctx.cache} (its renders would be "
                  "overwritten under it); wait for it, or give this one its own TMPDIR",
                  file=sys.stderr)
            return 2
        try:
            return _run(args, ctx)
        finally:
            if not args.keep_renders:
                clear_renders(ctx.cache)


def clear_renders(cache: Path) -> None:
    """Removes what a run rendered into ``cache`` (not its lock). Every section renders its
    recordings afresh, so they are scratch once the run is done; left behind, a full run's
    ~14 GB filled the disk that the next CI run shared with /tmp."""
    for entry in cache.iterdir():
        if entry.name == ".lock":
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)


@contextlib.contextmanager
def _cache_lock(cache: Path):
    """Yields whether this process holds the render cache: two runs rendering into one cache
    overwrite each other's recordings mid-read (a run measured that way reported a recording
    that tracks fine as 'failed to track')."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock, as before
        yield True
        return
    cache.mkdir(parents=True, exist_ok=True)
    with open(cache / ".lock", "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            yield False
            return
        yield True


def _run(args: argparse.Namespace, ctx: Context) -> int:
    options = "--quick" if args.quick else f"--seeds {args.seeds}"
    options += " --no-soak" if args.no_soak else ""
    blocks = read_blocks(args.out.read_text()) if args.out.is_file() else {}
    for name in args.only:
        start = time.perf_counter()
        summary, section = SECTIONS[name](ctx, {})
        command = f"python -m benchmarks.run --only {name} {options}"
        lines = [section[0], "", _provenance(name, command, time.perf_counter() - start),
                 *section[1:]]
        if args.print:
            print("\n".join([*summary, "", *lines]), flush=True)
            continue
        blocks["summary", name] = body(summary)
        blocks["bench", name] = body(lines)
        # written after every section, so an interrupted run keeps what it measured
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(compose(_intro(), tuple(SECTIONS), blocks))
        print(f"{name}: written to {args.out} ({(time.perf_counter() - start) / 60:.1f} min)",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
