"""`wristtrack batch`: a study of recordings on a Dask LocalCluster and on a local process pool,
with broken recordings isolated, the study table checked against the simulated truth, re-runs
skipping what is done and resuming what was interrupted."""

import json
import shutil
import sys

import numpy as np
import pytest

from wristtrack.analysis.summary import AXES
from wristtrack.cli import main
from wristtrack.errors import ConfigError
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses
from wristtrack.pipeline.batch import find_recordings, run_batch
from wristtrack.pipeline.checkpoint import CHECKPOINT_FILE
from wristtrack.pipeline.track import track_recording
from wristtrack.report.study import read_study_csv
from wristtrack.sim.render import render_recording

N_FRAMES = 30  # at 10 fps: the whole movement in 3 s, slow enough to be tracked well
GOOD = ("p01/deviation", "p01/flexion", "p02/deviation", "p02/flexion", "p03/deviation",
        "p03/flexion")
BROKEN = ("p03/missing_png", "p04/bad_camera")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """8 recordings: 6 good (copies of two rendered ones), 2 broken."""
    root = tmp_path_factory.mktemp("study")
    source = tmp_path_factory.mktemp("rendered")
    rendered = {
        name: render_recording(source / name, name, seed=3, n_frames=N_FRAMES, fps=10.0)
        for name in ("deviation", "flexion")
    }
    for name in GOOD:
        shutil.copytree(rendered[name.split("/")[1]], root / name)
    shutil.copytree(rendered["deviation"], root / BROKEN[0])
    (root / BROKEN[0] / "rgb" / "000007.png").unlink()  # frames.csv lists a missing PNG
    shutil.copytree(rendered["flexion"], root / BROKEN[1])
    (root / BROKEN[1] / "camera.json").write_text('{"fx": 500, "fy": ')  # cut short
    (root / ".hidden").mkdir()
    shutil.copytree(rendered["deviation"], root / ".hidden" / "copy")  # not part of the study
    return root


def _truth_ranges(study, name):
    truth = read_poses(study / name / "truth.csv")
    return {a: np.ptp(truth[f"{a}_deg"]) for a in AXES}


def _check_table(study, rows, good_status="ok"):
    by_name = {r["recording"]: r for r in rows}
    assert sorted(by_name) == sorted(GOOD + BROKEN)
    for name in GOOD:
        row = by_name[name]
        assert row["status"] == good_status and not row["error"]
        assert int(float(row["frames"])) == N_FRAMES
        assert int(float(row["frames_tracked"])) >= N_FRAMES - 1
        truth = _truth_ranges(study, name)
        for axis in AXES:  # the table's RoM is the tracked one: close to the simulated truth
            assert abs(float(row[f"{axis}_range_deg"]) - truth[axis]) < 4.0, (name, axis)
        assert float(row["peak_speed_m_s"]) > 0
        assert row["hand_layout"] == "hand.json"  # rendered with one: tracked once
    missing, camera = by_name[BROKEN[0]], by_name[BROKEN[1]]
    assert missing["status"] == camera["status"] == "failed"
    assert "000007.png" in missing["error"] and "not found" in missing["error"]
    assert "camera.json" in camera["error"] and "not valid JSON" in camera["error"]
    for row in (missing, camera):
        assert "\n" not in row["error"] and not row["frames"]


def test_batch_on_a_dask_local_cluster_isolates_the_broken_recordings(study, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster:
        rows = run_batch(study, out, dask=cluster.scheduler_address, progress=False, echo=None,
                         report=False)
    _check_table(study, rows)
    _check_table(study, read_study_csv(out / "study.csv"))  # the same on disk
    page = (out / "study.html").read_text()
    assert "data:image/png;base64," in page and all(n in page for n in GOOD + BROKEN)
    for name in GOOD:
        assert len(read_poses(out / name / "poses.csv")["frame"]) == N_FRAMES
    assert not (out / ".hidden").exists()


def test_batch_on_a_local_pool_then_rerun_skips_and_resumes(study, tmp_path, capsys, interrupt_at,
                                                             briefly_primed):
    out = tmp_path / "out"
    code = main(["batch", str(study), "--out", str(out), "--workers", "2", "--no-progress"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert code == 1  # some recordings failed
    assert len(lines) == 9 and "6 tracked, 0 already done, 2 failed" in lines[-1]
    _check_table(study, read_study_csv(out / "study.csv"))
    for name in GOOD:  # each tracked recording has its own report
        assert "<img" in (out / name / "report.html").read_text()

    # one run interrupted part-way (a real SIGINT at frame 9), one run tracked already
    name = GOOD[0]
    with open_recording(study / name) as recording, briefly_primed():
        interrupt_at(recording, 9)
        with pytest.raises(KeyboardInterrupt):
            track_recording(recording, out / name, progress=False, checkpoint_every=4)
    assert (out / name / CHECKPOINT_FILE).is_file()
    done = {n: (out / n / "summary.json").stat().st_mtime_ns for n in GOOD[1:]}

    rows = run_batch(study, out, workers=2, progress=False, echo=None, report=False)
    by_name = {r["recording"]: r for r in rows}
    assert by_name[name]["status"] == "ok"  # resumed from its checkpoint, now complete
    assert not (out / name / CHECKPOINT_FILE).exists()
    assert json.loads((out / name / "summary.json").read_text())["interrupted"] is False
    assert len(read_poses(out / name / "poses.csv")["frame"]) == N_FRAMES
    for n in GOOD[1:]:
        assert by_name[n]["status"] == "skipped"
        assert (out / n / "summary.json").stat().st_mtime_ns == done[n]  # not tracked again
    assert [by_name[n]["status"] for n in BROKEN] == ["failed", "failed"]


def test_find_recordings_by_kind(tmp_path):
    (tmp_path / "a" / "rec").mkdir(parents=True)
    (tmp_path / "a" / "rec" / "frames.csv").write_text("timestamp,rgb,depth\n")
    (tmp_path / "a" / "rec" / "rgb").mkdir()  # inside a recording: not searched
    (tmp_path / "a" / "rec" / "rgb" / "x.mp4").write_bytes(b"")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "take1.mp4").write_bytes(b"")
    (tmp_path / "b" / "take1.camera.json").write_text("{}")
    (tmp_path / "b" / "take2.avi").write_bytes(b"")
    (tmp_path / "b" / "session.bag").write_bytes(b"")
    (tmp_path / "c" / "ros2").mkdir(parents=True)
    (tmp_path / "c" / "ros2" / "metadata.yaml").write_text("")
    (tmp_path / "out" / "x").mkdir(parents=True)
    (tmp_path / "out" / "x" / "frames.csv").write_text("")  # the batch's own output
    jobs = {j.name: j for j in find_recordings(tmp_path, exclude=tmp_path / "out")}
    assert sorted(jobs) == ["a/rec", "b/session.bag", "b/take1.mp4", "b/take2.avi", "c/ros2"]
    assert jobs["b/take1.mp4"].camera == str(tmp_path / "b" / "take1.camera.json")
    assert jobs["b/take2.avi"].camera is None


def test_batch_errors_are_one_line(study, tmp_path, monkeypatch, capsys):
    code = main(["batch", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "not found" in err
    (tmp_path / "empty").mkdir()
    code = main(["batch", str(tmp_path / "empty"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "no recordings" in err
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # as if dask were not installed
    with pytest.raises(ConfigError, match=r"pip install 'wristtrack\[cluster\]'"):
        run_batch(study, tmp_path / "o", dask="tcp://127.0.0.1:8786", progress=False, echo=None)
