"""poses.csv / truth.csv read back by the one reader (io.poses): every column, a few columns
streamed, the raw text rows; interrupted and damaged files. Truth is the writer's own rows
(written from a known trajectory) and hand-spoilt copies of them."""

import math

import numpy as np
import pytest

from wristtrack.errors import InputError
from wristtrack.io.poses import COLUMNS, read_pose_table, read_poses, write_truth
from wristtrack.sim.motion import scenario


@pytest.fixture(scope="module")
def truth_lines(tmp_path_factory):
    """The lines of a truth.csv written from a 'mix' trajectory (kept with their newlines),
    and the trajectory."""
    tr, _, _ = scenario("mix", rng=2)
    path = tmp_path_factory.mktemp("poses") / "truth.csv"
    write_truth(path, tr)
    return path.read_text().splitlines(keepends=True), tr


def test_every_column_round_trips(truth_lines, tmp_path):
    lines, tr = truth_lines
    path = tmp_path / "truth.csv"
    path.write_text("".join(lines))
    cols = read_poses(path)
    assert list(cols) == list(COLUMNS)
    assert len(cols["frame"]) == len(tr.t)
    np.testing.assert_array_equal(cols["timestamp"], tr.t)  # repr(): exact
    np.testing.assert_allclose(np.column_stack([cols[c] for c in ("tx", "ty", "tz")]), tr.p_rel,
                               rtol=1e-8, atol=1e-12)  # 9 significant digits
    assert set(cols["status"]) == {"truth"}
    header, rows = read_pose_table(path)
    assert header == list(COLUMNS)
    assert ["".join(",".join(r) + "\n") for r in rows] == lines[1:]


def test_selected_columns_equal_the_whole_read(truth_lines, tmp_path):
    lines, tr = truth_lines
    path = tmp_path / "truth.csv"
    lines = list(lines)
    lines[5] = lines[5].replace("truth", "lost")
    cut = lines + [lines[7][:25]]  # a last row cut short by an interrupted run (no newline)
    path.write_text("".join(cut))
    want = read_poses(path)
    names = ("timestamp", "status", "vx", "flexion_deg")
    got = read_poses(path, columns=names)
    assert list(got) == list(names)
    assert len(got["timestamp"]) == len(tr.t)
    for name in names:
        np.testing.assert_array_equal(got[name], want[name])
    assert got["status"][4] == "lost"


def test_interrupted_and_damaged_files(truth_lines, tmp_path):
    lines, tr = truth_lines
    path = tmp_path / "poses.csv"
    # A whole row without its newline was cut just before it: dropped as well.
    path.write_text("".join(lines)[:-1])
    assert len(read_poses(path)["frame"]) == len(tr.t) - 1
    # A short row followed by others is damage, not an interruption.
    path.write_text("".join(lines[:4] + [lines[4][:30] + "\n"] + lines[5:]))
    with pytest.raises(InputError, match="line 5: .* cells"):
        read_poses(path)
    path.write_text("".join(lines[:3] + [lines[3].replace(",", ",x", 1)] + lines[4:]))
    with pytest.raises(InputError, match="column timestamp holds a non-number"):
        read_poses(path)
    with pytest.raises(InputError, match="has no column nope"):
        read_poses(tmp_path / "poses.csv", columns=("nope",))
    # only the header: empty columns, not an error
    path.write_text(lines[0])
    cols = read_poses(path)
    assert cols["frame"].shape == (0,) and cols["status"].shape == (0,)


def test_not_a_poses_file(tmp_path):
    bad = tmp_path / "frames.csv"
    bad.write_text("timestamp,rgb,depth\n0.0,rgb/0.png,\n")
    with pytest.raises(InputError, match="not a poses.csv"):
        read_poses(bad)
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(InputError, match="not a poses.csv"):
        read_poses(tmp_path / "empty.csv")
    with pytest.raises(InputError, match="cannot read"):
        read_poses(tmp_path / "missing.csv")
    (tmp_path / "latin1.csv").write_bytes(b"frame,\xe9t\xe9\n")
    with pytest.raises(InputError, match="cannot read"):
        read_poses(tmp_path / "latin1.csv")


def test_nan_cells_read_as_nan(truth_lines, tmp_path):
    lines, _ = truth_lines
    cells = lines[2].rstrip("\n").split(",")
    cells[3:26] = ["nan"] * 23
    cells[26] = ""  # an empty cell is NaN too
    path = tmp_path / "poses.csv"
    path.write_text("".join([lines[0], lines[1], ",".join(cells) + "\n"]))
    cols = read_poses(path)
    assert math.isnan(cols["cam_tx"][1]) and math.isnan(cols["n_visible"][1])
    assert math.isfinite(cols["cam_tx"][0])
