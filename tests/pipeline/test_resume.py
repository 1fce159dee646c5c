"""Interrupted runs: poses.csv stays valid when a run is killed, and --resume finishes it with
exactly the result of a run that was never interrupted."""

import importlib.util
import json
import shutil
import signal
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from wristtrack.cli import main
from wristtrack.errors import InputError
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses
from wristtrack.io.run_folder import REFIT_DIR
from wristtrack.pipeline.checkpoint import CHECKPOINT_FILE, completed_summary, resumable
from wristtrack.pipeline.track import track_recording
from wristtrack.tracking.noise_scale import primes
from wristtrack.tracking.tracker import TrackerConfig

N_FRAMES = 48


@pytest.fixture(scope="module", autouse=True)
def _brief_priming(briefly_primed):
    """Interrupts part-way need a priming shorter than these recordings (conftest)."""
    with briefly_primed():
        yield


@pytest.fixture(scope="module")
def rec(rendered):
    return rendered("reach", seed=0, n_frames=N_FRAMES)


@pytest.fixture(scope="module")
def reference(rec, tmp_path_factory):
    """An uninterrupted run of the recording."""
    out = tmp_path_factory.mktemp("reference")
    with open_recording(rec) as recording:
        track_recording(recording, out, progress=False)
    return out


def _run_interrupted(interrupt_at, rec, out, index, nth=1, **kw):
    with open_recording(rec) as recording:
        interrupt_at(recording, index, nth)
        with pytest.raises(KeyboardInterrupt):
            track_recording(recording, out, progress=False, checkpoint_every=10, **kw)


def _resume(rec, out, **kw):
    with open_recording(rec) as recording:
        return track_recording(recording, out, progress=False, resume=True, **kw)


def _summary(out):
    return json.loads((out / "summary.json").read_text())


def _data_lines(path):
    return path.read_bytes().splitlines(keepends=True)[1:]


@pytest.mark.parametrize("index", [23, N_FRAMES - 1])
def test_interrupt_then_resume_gives_the_uninterrupted_result(rec, reference, tmp_path, index,
                                                              interrupt_at):
    out = tmp_path / "run"
    _run_interrupted(interrupt_at, rec, out, index)
    # stopped at a frame boundary, at most a few frames before the one being read ahead as the
    # Ctrl-C came: the uninterrupted run's rows up to there, all complete
    kept = _data_lines(out / "poses.csv")
    assert _primed_frames(rec) < len(kept) <= index
    assert kept == _data_lines(reference / "poses.csv")[: len(kept)]
    assert _summary(out)["interrupted"] is True
    assert (out / CHECKPOINT_FILE).is_file()
    summary = _resume(rec, out)
    assert (out / "poses.csv").read_bytes() == (reference / "poses.csv").read_bytes()
    assert summary == _summary(reference)  # accumulated state carried over exactly
    assert not (out / CHECKPOINT_FILE).exists()


def _primed_frames(rec) -> int:
    """How many of the recording's first frames prime the noise (briefly, see above)."""
    times = np.loadtxt(rec / "frames.csv", delimiter=",", skiprows=1, usecols=0)
    return int(sum(primes(t, times[0]) for t in times))


def test_interrupted_while_priming_the_noise_resumes_to_the_uninterrupted_result(
        rec, reference, tmp_path, interrupt_at):
    """A Ctrl-C while the first seconds prime the noise (pipeline/priming.py) stops the run
    once they are tracked: their rows written, a checkpoint at the next frame, from which
    --resume gives the run that was never interrupted."""
    out = tmp_path / "run"
    primed = _primed_frames(rec)
    assert 3 < primed < N_FRAMES // 2
    _run_interrupted(interrupt_at, rec, out, 2)
    assert _data_lines(out / "poses.csv") == _data_lines(reference / "poses.csv")[:primed]
    assert (out / CHECKPOINT_FILE).is_file()
    _resume(rec, out)
    assert (out / "poses.csv").read_bytes() == (reference / "poses.csv").read_bytes()
    assert _summary(out) == _summary(reference)


def test_interrupted_smoothed_run_resumes_to_the_same_smoothed_result(rec, tmp_path,
                                                                     interrupt_at):
    full, part = tmp_path / "full", tmp_path / "part"
    with open_recording(rec) as recording:
        track_recording(recording, full, progress=False, smooth=True)
    _run_interrupted(interrupt_at, rec, part, 30, smooth=True)
    _resume(rec, part, smooth=True)
    for name in ("poses.csv", "poses_filtered.csv", "filter_states.f64"):
        if (full / name).exists():
            assert (part / name).read_bytes() == (full / name).read_bytes(), name


def test_run_interrupted_in_its_refit_keeps_the_first_and_resumes_to_the_same_result(
        rec, tmp_path, interrupt_at):
    """A Ctrl-C while --smooth tracks the recording again at the learned noise
    (pipeline/refit.py): the finished first run stays whole in the run folder, and --resume
    completes the refit to the result of a run never interrupted."""
    full, part = tmp_path / "full", tmp_path / "part"
    learned = TrackerConfig(smoothing_noise="learned")
    with open_recording(rec) as recording:
        track_recording(recording, full, learned, progress=False, smooth=True)
    assert _summary(full)["smoothing_process_noise"]["refit_kept"] is True
    _run_interrupted(interrupt_at, rec, part, 30, nth=2, smooth=True,  # its second reading
                     config=learned)
    first = _summary(part)
    assert first["interrupted"] is False and "smoothing_process_noise" not in first
    assert (part / "poses_filtered.csv").is_file()
    assert (part / REFIT_DIR / CHECKPOINT_FILE).is_file()
    assert _summary(part / REFIT_DIR)["interrupted"] is True
    # not complete (batch runs it again), and resumed only as it was started
    assert completed_summary(part) is None and resumable(part)
    with pytest.raises(InputError, match="learned noise; resume it with the options"):
        _resume(rec, part, smooth=True)  # the model's noise: the default
    _resume(rec, part, smooth=True, config=learned)
    assert not (part / REFIT_DIR).exists()
    for name in ("poses.csv", "poses_filtered.csv"):
        assert (part / name).read_bytes() == (full / name).read_bytes(), name
    assert _summary(part) == _summary(full)


@pytest.fixture(scope="module")
def unprimed(rec, tmp_path_factory):
    """An uninterrupted run of the recording that does not prime the noise: the killed runs
    below are `wristtrack` children, which would prime over 10 s, all of this recording, and
    so write nothing until they had tracked all of it."""
    out = tmp_path_factory.mktemp("unprimed")
    with open_recording(rec) as recording:
        track_recording(recording, out, TrackerConfig(prime_noise=False), progress=False)
    return out


def _start(rec, out):
    cmd = [sys.executable, "-m", "wristtrack.cli", "track", str(rec), "--out", str(out),
           "--no-progress", "--no-report", "--checkpoint-every", "4", "--no-prime-noise"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.send_signal(signal.SIGSTOP)  # it runs only in the bursts _run_until_rows allows
    return proc


def _run_until_rows(proc, path, rows, timeout=180.0):
    """Let the stopped run go on in short bursts (SIGCONT, a few ms, SIGSTOP) until poses.csv
    holds more than ``rows`` rows; it is left stopped. A burst is far shorter than the rest of
    the run, so the run is caught part-way however fast or busy the machine is."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        started = path.exists()
        proc.send_signal(signal.SIGCONT)
        time.sleep(0.003 if started else 0.05)  # start-up (imports, compiling) in long bursts
        proc.send_signal(signal.SIGSTOP)
        assert proc.poll() is None, "the run ended before it could be interrupted"
        if started and path.read_bytes().count(b"\n") > rows:
            return
    raise AssertionError("no rows appeared")


def _check_poses(check_run, path):
    """The contract checker's poses.csv checks (shared/tools/check_run.py)."""
    spec = importlib.util.spec_from_file_location("check_run", check_run)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.check_poses(path)


def _cli_resume(rec, out):
    return subprocess.run(
        [sys.executable, "-m", "wristtrack.cli", "track", str(rec), "--out", str(out),
         "--no-progress", "--no-report", "--resume", "--no-prime-noise"],
        capture_output=True, text=True, check=False,
    )


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_killed_cli_run_keeps_a_valid_poses_csv_and_resumes(rec, unprimed, tmp_path, sig,
                                                             check_run):
    out = tmp_path / "run"
    proc = _start(rec, out)
    _run_until_rows(proc, out / "poses.csv", 12)
    proc.send_signal(sig)  # a real signal, wherever the run happens to be in its frame
    proc.send_signal(signal.SIGCONT)
    _, err = proc.communicate(timeout=180)
    kept = _data_lines(out / "poses.csv")
    assert 12 <= len(kept) < N_FRAMES
    # every row there is whole and is the uninterrupted run's row
    assert kept == _data_lines(unprimed / "poses.csv")[: len(kept)]
    assert len(read_poses(out / "poses.csv")["frame"]) == len(kept)
    assert _check_poses(check_run, out / "poses.csv") == []
    if sig == signal.SIGINT:
        assert proc.returncode == 130
        assert len(err.strip().splitlines()) == 1 and "--resume" in err
        assert _summary(out)["interrupted"] is True
        checked = subprocess.run([sys.executable, str(check_run), str(out)],
                                 capture_output=True, text=True, check=False)
        assert checked.returncode == 0, checked.stdout
    else:
        assert proc.returncode == -signal.SIGKILL
        assert not (out / "summary.json").exists()
    done = _cli_resume(rec, out)
    assert done.returncode == 0, done.stderr
    assert (out / "poses.csv").read_bytes() == (unprimed / "poses.csv").read_bytes()
    assert not (out / CHECKPOINT_FILE).exists()


def _cli_error(capsys, *argv):
    code = main(list(argv))
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return code, err


def test_resume_refusals_are_one_line(rec, tmp_path, capsys, interrupt_at):
    out = tmp_path / "run"
    code, err = _cli_error(capsys, "track", str(rec), "--out", str(out), "--resume",
                           "--no-progress")
    assert code == 2 and "nothing to resume" in err

    _run_interrupted(interrupt_at, rec, out, 20)
    code, err = _cli_error(capsys, "track", str(rec), "--out", str(out), "--resume",
                           "--no-progress", "--no-depth")
    assert code == 2 and "settings (use_depth)" in err

    other = tmp_path / "other"
    shutil.copytree(rec, other)
    lines = (other / "frames.csv").read_text().splitlines(keepends=True)
    (other / "frames.csv").write_text("".join(lines[:-1]))  # one frame fewer
    code, err = _cli_error(capsys, "track", str(other), "--out", str(out), "--resume",
                           "--no-progress")
    assert code == 2 and "input recording" in err

    code, err = _cli_error(capsys, "track", str(rec), "--out", str(out), "--resume",
                           "--no-progress", "--overlay", str(tmp_path / "o.mp4"))
    assert code == 2 and "--overlay" in err

    poses = (out / "poses.csv").read_bytes()
    (out / "poses.csv").write_bytes(poses[:100])
    code, err = _cli_error(capsys, "track", str(rec), "--out", str(out), "--resume",
                           "--no-progress")
    assert code == 2 and "poses.csv" in err and "without --resume" in err
    (out / "poses.csv").write_bytes(poses)

    checkpoint = (out / CHECKPOINT_FILE).read_bytes()
    (out / CHECKPOINT_FILE).write_bytes(checkpoint[: len(checkpoint) // 2])
    code, err = _cli_error(capsys, "track", str(rec), "--out", str(out), "--resume",
                           "--no-progress")
    assert code == 2 and "cannot be read" in err
    # a fresh run over it starts again and leaves no checkpoint behind
    assert main(["track", str(rec), "--out", str(out), "--no-progress", "--no-report"]) == 0
    assert not (out / CHECKPOINT_FILE).exists()
    capsys.readouterr()
    # nothing left to do: says so, exit 0
    assert main(["track", str(rec), "--out", str(out), "--resume", "--no-progress"]) == 0
    assert "already complete" in capsys.readouterr().out


def test_read_poses_drops_a_last_line_cut_short(reference, tmp_path):
    full = (reference / "poses.csv").read_bytes()
    whole = read_poses(reference / "poses.csv")
    for cut in (1, 5, 40):  # a cut inside the last number still leaves the cells count right
        (tmp_path / "poses.csv").write_bytes(full[:-cut])
        got = read_poses(tmp_path / "poses.csv")
        assert len(got["frame"]) == N_FRAMES - 1
        np.testing.assert_array_equal(got["tx"], whole["tx"][:-1])


def test_recording_frames_start_part_way_without_reading_the_skipped_images(rec, tmp_path):
    copy = tmp_path / "rec"
    shutil.copytree(rec, copy)
    with open_recording(copy) as recording:
        full = list(recording)
    # (opening reads the first three frames to check the recording; later ones only if asked)
    for name in sorted((copy / "rgb").iterdir())[3:10]:
        name.write_bytes(b"")  # would be a bad frame if it were read
    with open_recording(copy) as recording:
        part = list(recording.frames(10))
    assert [f.index for f in part] == list(range(10, N_FRAMES))
    for a, b in zip(part, full[10:], strict=True):
        assert a.ok and a.timestamp == b.timestamp
        assert np.array_equal(a.bgr, b.bgr) and np.array_equal(a.depth, b.depth)


def test_video_frames_start_part_way(rec, tmp_path):
    path = tmp_path / "v.avi"
    with open_recording(rec) as recording:
        camera = recording.camera
        size = (camera.width, camera.height)
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, size)
        for frame in recording:
            if frame.index == 12:
                break
            writer.write(frame.bgr)
        writer.release()
    with open_recording(path, camera=camera) as video:
        full = list(video)
        part = list(video.frames(5))
    assert [f.index for f in part] == list(range(5, 12))
    for a, b in zip(part, full[5:], strict=True):
        assert a.timestamp == b.timestamp and np.array_equal(a.bgr, b.bgr)
