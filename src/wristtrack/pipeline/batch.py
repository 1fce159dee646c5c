"""``wristtrack batch STUDY_DIR --out OUT``: every recording of a study, in parallel.

Recordings are found the way ``wristtrack track`` opens them: a folder with frames.csv, a ROS 2
bag folder (metadata.yaml), a ROS 1 ``.bag`` file or a video file (whose camera.json is
``NAME.camera.json`` or ``camera.json`` beside it; ``NAME.hand.json`` or ``hand.json`` likewise).
Each is tracked into ``OUT/<its path under STUDY_DIR>/`` by a worker: a local process pool
(``workers``) or, with ``dask="tcp://host:port"``, the workers of an existing Dask cluster (they
must see STUDY_DIR and OUT at the same paths, e.g. on a shared file system).

A failure is confined to its recording: the worker returns the error's one line for the study
table instead of raising. ``OUT/study.csv`` is rewritten (atomically) as each recording
finishes, ``OUT/study.html`` at the end. Running the batch again skips the recordings whose
run is complete (unless ``force``) and resumes those that were interrupted, from their
checkpoints.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wristtrack.errors import ConfigError, InputError, WristtrackError
from wristtrack.io.video import VIDEO_SUFFIXES
from wristtrack.pipeline.checkpoint import (
    CHECKPOINT_FRAMES,
    CheckpointMismatch,
    completed_summary,
    resumable,
)
from wristtrack.report.study import (
    one_line,
    row_from_summary,
    row_without_run,
    write_study_csv,
    write_study_html,
)

# Thread pools of numerical libraries, one thread each per worker: N workers on N cores
# otherwise fight over them. (Read when a library loads, so set before the workers start.)
THREAD_ENV = (
    "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS", "NUMBA_NUM_THREADS",
)
STUDY_CSV, STUDY_HTML = "study.csv", "study.html"


@dataclass(frozen=True)
class Job:
    """One recording of the study."""

    name: str  # its path under the study folder ("/"-separated): also its output folder
    source: str
    camera: str | None = None  # camera.json for a video
    hand: str | None = None


# ------------------------------------------------------------------------------ discovery


def _beside(path: Path, kind: str) -> str | None:
    for candidate in (path.with_name(f"{path.stem}.{kind}.json"), path.parent / f"{kind}.json"):
        if candidate.is_file():
            return str(candidate)
    return None


def find_recordings(study: str | Path, exclude: str | Path | None = None) -> list[Job]:
    """Every recording under ``study`` (not under ``exclude``, nor in hidden folders), sorted.
    Sources are absolute paths, so workers with another working folder (Dask) find them."""
    study = Path(study).resolve()
    skip = Path(exclude).resolve() if exclude is not None else None
    jobs = []
    for folder, dirs, files in os.walk(study):
        here = Path(folder)
        if skip is not None and here.resolve() == skip:
            dirs.clear()
            continue
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        name = here.relative_to(study).as_posix()
        if "frames.csv" in files or "metadata.yaml" in files:  # a recording / ROS 2 bag folder
            jobs.append(Job(name if name != "." else here.resolve().name, str(here)))
            dirs.clear()
            continue
        for file in sorted(files):
            path = here / file
            suffix = path.suffix.lower()
            if suffix == ".bag":
                jobs.append(Job(path.relative_to(study).as_posix(), str(path)))
            elif suffix in VIDEO_SUFFIXES:
                jobs.append(Job(path.relative_to(study).as_posix(), str(path),
                                _beside(path, "camera"), _beside(path, "hand")))
    return sorted(jobs, key=lambda j: j.name)


# --------------------------------------------------------------------------------- worker


_POOL_WORKER = False  # set in the processes of the local pool


def _pool_worker() -> None:
    global _POOL_WORKER
    _POOL_WORKER = True
    limit_threads()


def limit_threads() -> None:
    """One thread per worker for OpenCV and (where not loaded yet) the BLAS libraries."""
    for name in THREAD_ENV:
        os.environ.setdefault(name, "1")
    import cv2

    cv2.setNumThreads(1)


def track_one(
    job: Job, out: str, config: Any = None, force: bool = False,
    checkpoint_every: int = CHECKPOINT_FRAMES, smooth: bool = False, report: bool = True,
    survey: bool = True,
) -> dict[str, Any]:
    """Track one recording into ``out`` (resuming an interrupted run unless ``force``), smoothed
    if asked, its layout surveyed unless ``survey`` is False (pipeline.track), with its
    report.html unless ``report`` is False; its study row. Never raises for a
    problem with the recording: the row says ``failed``."""
    from wristtrack.camera import Camera
    from wristtrack.hand import HandLayout
    from wristtrack.io.open import open_recording
    from wristtrack.pipeline.track import track_recording

    limit_threads()
    try:
        suffix = Path(job.source).suffix.lower()
        if suffix in VIDEO_SUFFIXES and job.camera is None:
            raise ConfigError(
                f"video {job.source} has no camera.json beside it; add "
                f"{Path(job.source).stem}.camera.json (or camera.json) to its folder"
            )
        camera = Camera.load(job.camera) if job.camera else None
        hand = HandLayout.load(job.hand) if job.hand else None
        resume = not force and resumable(out)
        with open_recording(job.source, camera=camera, hand=hand) as recording:
            kw = {"progress": False, "checkpoint_every": checkpoint_every, "smooth": smooth,
                  "survey": survey}
            try:
                summary = track_recording(recording, out, config, resume=resume, **kw)
            except CheckpointMismatch:  # the recording or the settings changed: start over
                summary = track_recording(recording, out, config, **kw)
        if report:
            from wristtrack.report.html import write_report

            write_report(out)
        return row_from_summary(job.name, "ok", summary)
    except KeyboardInterrupt:
        if _POOL_WORKER:  # the batch stopped us (SIGTERM), the run is checkpointed: take no
            os._exit(130)  # further task from the pool's queue
        raise
    except WristtrackError as exc:
        return row_without_run(job.name, "failed", str(exc))
    except Exception as exc:  # a bug must not stop the study either; say it is one
        return row_without_run(
            job.name, "failed", f"{type(exc).__name__}: {exc} (unexpected; please report it)"
        )


# -------------------------------------------------------------------------------- runners


@contextmanager
def _single_threaded_env() -> Iterator[None]:
    """THREAD_ENV set to 1 while the pool's processes start (they inherit it)."""
    saved = {name: os.environ.get(name) for name in THREAD_ENV}
    os.environ.update(dict.fromkeys(THREAD_ENV, "1"))
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


Runner = Iterator[tuple[Job, dict[str, Any]]]


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _run_pool(jobs: list[Job], out: Path, workers: int, args: tuple) -> Runner:
    # spawn: fresh interpreters, no inherited threads (tqdm's monitor) or library state
    context = multiprocessing.get_context("spawn")
    with _single_threaded_env():
        pool = ProcessPoolExecutor(min(workers, len(jobs)), context, initializer=_pool_worker)
        try:
            # The workers start (all at once) at the first submit. They ignore SIGINT, so a
            # Ctrl-C reaches only this process, which then stops them with SIGTERM: a worker
            # tracking then checkpoints and stops, one starting up just ends, no traceback.
            handler = signal.signal(signal.SIGINT, signal.SIG_IGN) if _main_thread() else None
            try:
                futures = {
                    pool.submit(track_one, job, str(out / job.name), *args): job for job in jobs
                }
            finally:
                if handler is not None:
                    signal.signal(signal.SIGINT, handler)
            for future in as_completed(futures):
                job = futures[future]
                try:
                    row = future.result()
                except BrokenProcessPool:
                    row = row_without_run(
                        job.name, "failed", "the worker process died while tracking it (out of "
                        "memory, or killed); run the batch again to retry it",
                    )
                yield job, row
        except BaseException:
            # Ctrl-C or the caller stopped: SIGTERM makes each worker checkpoint and stop
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(jobs: list[Job], out: Path, address: str, args: tuple) -> Runner:
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise ConfigError(
            "--dask needs dask.distributed; install it with pip install 'wristtrack[cluster]'"
        ) from None
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(
            f"cannot connect to the Dask scheduler at {address} ({one_line(exc)}); start it "
            "(dask scheduler) or check the address"
        ) from None
    with client:  # closes our connection, never the cluster
        batch = uuid.uuid4().hex[:8]
        futures = {
            client.submit(
                track_one, job, str(out.resolve() / job.name), *args,
                key=f"wristtrack-{batch}-{i}", pure=False,
            ): job
            for i, job in enumerate(jobs)
        }
        try:
            for future in dask_completed(list(futures)):
                job = futures[future]
                try:
                    row = future.result()
                except Exception as exc:  # the task itself failed (a worker died, ...)
                    row = row_without_run(job.name, "failed", f"Dask: {type(exc).__name__}: {exc}")
                yield job, row
        except BaseException:
            client.cancel(list(futures))
            raise


# ---------------------------------------------------------------------------------- batch


def _line(row: dict[str, Any]) -> str:
    if row["status"] == "failed":
        return f"failed  {row['recording']}: {row['error']}"
    return (f"{row['status']:<7} {row['recording']}: {row['frames_tracked']} of "
            f"{row['frames']} frames tracked")


def run_batch(
    study: str | Path,
    out: str | Path,
    config: Any = None,
    workers: int | None = None,
    dask: str | None = None,
    force: bool = False,
    progress: bool = True,
    checkpoint_every: int = CHECKPOINT_FRAMES,
    echo: Callable[[str], None] | None = print,
    smooth: bool = False,
    report: bool = True,
    survey: bool = True,
) -> list[dict[str, Any]]:
    """Track every recording under ``study`` into ``out``; the study rows, in name order.

    ``workers`` processes (default: one per CPU), or the Dask cluster at ``dask``. ``echo``
    gets one line per finished recording.
    """
    study, out = Path(study), Path(out)
    if not study.is_dir():
        what = "is not a folder" if study.exists() else "not found"
        raise InputError(f"study folder {study} {what}; give the folder holding the recordings")
    jobs = find_recordings(study, exclude=out)
    if not jobs:
        raise InputError(
            f"no recordings under {study} (folders with frames.csv, video files, .bag files or "
            "ROS 2 bag folders); check the path"
        )
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise InputError(f"--workers {workers}: give a whole number >= 1")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            f"cannot create the output folder {out} ({exc.strerror}); give --out a folder you "
            "can write to"
        ) from None

    rows: dict[str, dict[str, Any]] = {}
    todo = []
    for job in jobs:
        done = None if force else completed_summary(out / job.name)
        if done is not None:
            rows[job.name] = row_from_summary(job.name, "skipped", done)
        else:
            rows[job.name] = row_without_run(job.name, "pending")
            todo.append(job)

    def table() -> list[dict[str, Any]]:
        return [rows[job.name] for job in jobs]

    write_study_csv(out / STUDY_CSV, table())
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), initial=len(jobs) - len(todo), unit="recording",
               desc="batch", disable=not progress)
    say = bar.write if progress else echo
    args = (config, force, checkpoint_every, smooth, report, survey)
    try:
        if todo:
            runner = (_run_dask(todo, out, dask, args) if dask
                      else _run_pool(todo, out, workers, args))
            for job, row in runner:
                rows[job.name] = row
                write_study_csv(out / STUDY_CSV, table())
                if say is not None:
                    say(_line(row))
                bar.update(1)
    finally:
        bar.close()
        write_study_csv(out / STUDY_CSV, table())
        write_study_html(out / STUDY_HTML, table(), f"wristtrack study: {study.name}")
    return table()
