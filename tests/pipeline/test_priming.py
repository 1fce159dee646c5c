"""The noise's priming as `track` runs it (pipeline/priming.py): every frame read and detected
once, the first seconds tracked twice, and the detections held for it capped in memory."""

from __future__ import annotations

import pytest

from wristtrack.io.open import open_recording
from wristtrack.pipeline import priming
from wristtrack.pipeline.track import track_recording
from wristtrack.tracking import noise_scale


@pytest.fixture(scope="module")
def rec(rendered):
    return rendered("reach", seed=0, n_frames=40)  # shared with the report tests


def _count_reads(recording) -> dict[int, int]:
    frames, reads = recording.frames, {}

    def counted(start=0):
        for frame in frames(start):
            reads[frame.index] = reads.get(frame.index, 0) + 1
            yield frame

    recording.frames = counted
    return reads


def test_a_primed_run_reads_each_frame_once(rec, tmp_path):
    with open_recording(rec) as recording:
        n = len(recording)
        reads = _count_reads(recording)
        summary = track_recording(recording, tmp_path / "run", progress=False)
    assert summary["settings"]["prime_noise"] is True
    assert summary["frames"]["total"] == n
    assert reads == {i: 1 for i in range(n)}


def _poses(rec, out, *patches) -> bytes:
    """poses.csv of a run with ``patches`` (module, name, value) in place."""
    with pytest.MonkeyPatch.context() as patch:
        for module, name, value in patches:
            patch.setattr(module, name, value)
        with open_recording(rec) as recording:
            track_recording(recording, out, progress=False)
    return (out / "poses.csv").read_bytes()


def test_the_held_detections_are_capped(rec, tmp_path):
    """Past HELD_BYTES the priming ends with the frames it has: with room for four depth
    frames, the run is the one primed over the first five frames (the cap is passed once the
    fifth is held), not the one primed over all of them."""
    with open_recording(rec) as recording:
        camera, times = recording.camera, recording.timestamps()
    depth_frame = camera.width * camera.height * 2  # uint16
    capped = _poses(rec, tmp_path / "capped", (priming, "HELD_BYTES", 4 * depth_frame))
    five = _poses(rec, tmp_path / "five",
                  (noise_scale, "PRIMING_S", 0.5 * (times[4] + times[5]) - times[0]))
    whole = _poses(rec, tmp_path / "whole")
    assert capped == five
    assert capped != whole
