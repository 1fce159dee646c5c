"""benchmarks.same_poses: which differences between two sets of runs count as behaviour."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.same_poses import main

HEADER = "frame,timestamp,status,tx,qw,n_visible"
ROWS = [
    "0,0.0,tracking,0.0599542024,0.999982885,6",
    "1,0.0333333333,coasting,0.0600000001,0.999900001,0",
    "2,0.0666666667,lost,nan,nan,0",
]


def _run(root: Path, name: str, rows: list[str]) -> None:
    (root / name).mkdir(parents=True)
    (root / name / "poses.csv").write_text("\n".join([HEADER, *rows]) + "\n")


def _changed(row: int, column: int, cell: str) -> list[str]:
    rows = [r.split(",") for r in ROWS]
    rows[row][column] = cell
    return [",".join(r) for r in rows]


@pytest.mark.parametrize(
    ("rows", "code"),
    [
        (ROWS, 0),
        (_changed(0, 3, "0.0599542025"), 0),  # one unit in the last printed digit
        (_changed(0, 3, "0.0599542124"), 1),  # 1e-8 of the column's scale
        (_changed(1, 2, "tracking"), 1),  # status
        (_changed(2, 3, "0.06"), 1),  # a value where there was none
        (_changed(0, 5, "5"), 1),  # integer columns are exact
        (ROWS[:2], 1),  # a row missing
    ],
)
def test_differences_that_count(tmp_path, capsys, rows, code):
    _run(tmp_path / "a", "reach", ROWS)
    _run(tmp_path / "b", "reach", rows)
    assert main([str(tmp_path / "a"), str(tmp_path / "b")]) == code
    line = capsys.readouterr().out.strip()
    assert line.startswith("reach: " + ("same" if code == 0 else "DIFFERENT"))


def test_one_line_per_run_and_a_missing_run_differs(tmp_path, capsys):
    for name in ("flexion", "reach"):
        _run(tmp_path / "a", name, ROWS)
    _run(tmp_path / "b", "reach", ROWS)
    assert main([str(tmp_path / "a"), str(tmp_path / "b")]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("flexion: DIFFERENT: no poses.csv")
    assert lines[1].startswith("reach: same")


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main([str(tmp_path / "nowhere"), str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: no poses.csv in") and "\n" not in err
