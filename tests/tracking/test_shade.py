"""A right hand making the left hand's movement (ulnar deviation with supination at extension)
under every camera effect: its back turns away from the lamp, the markers fall into the shade,
dark and desaturated, and the colour reference drops most of them for 10-15 frames. Rendered
(benchmarks.robustness' "all, right hand, mirrored movement"), detector + tracker as ``track``
runs them, scored against the simulator's truth."""

import numpy as np
import pytest

from wristtrack.geometry import rotation_distance
from wristtrack.io.open import open_recording
from wristtrack.io.poses import read_poses, rows_to_poses
from wristtrack.pipeline.track import track_recording
from wristtrack.tracking.tracker import Status


@pytest.mark.parametrize("seed", [5, 9])
def test_a_hand_turned_into_the_lamps_shade_is_tracked_through_it(seed, tmp_path):
    """Seed 9: the colour search finds 0-1 of six markers over frames 137-146; the search by
    chromaticity in the last tracking window finds them (before: coasting 40 deg off). Seed 5:
    four blobs, all doubted (three knuckles merged); a manoeuvre retry among them had taken a
    labelling shifted by one knuckle, 60-86 deg off while reported as tracking. Every frame
    with an estimate is now within a few degrees."""
    from benchmarks.robustness import render_condition

    rec = render_condition(tmp_path / "rec", "all, right hand, mirrored movement", seed, 160)
    out = tmp_path / "run"
    track_recording(open_recording(rec), out, progress=False)
    poses, truth = read_poses(out / "poses.csv"), read_poses(rec / "truth.csv")
    R, _ = rows_to_poses(poses)
    R_true, _ = rows_to_poses(truth)
    estimated = np.isfinite(R).all(axis=(1, 2))
    err = np.degrees(rotation_distance(R[estimated], R_true[estimated]))
    assert estimated.mean() >= 0.98
    assert err.max() < 4.0, (err.max(), int(np.argmax(err)))
    assert np.sqrt(np.mean(err**2)) < 1.0
    lost = sum(s == Status.LOST.value for s in poses["status"])
    assert lost <= 3
