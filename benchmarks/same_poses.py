"""Whether two sets of runs wrote the same poses: ``python -m benchmarks.same_poses DIR_A DIR_B``.

Each run is a folder with a poses.csv (DIR itself, or its sub-folders, matched by name). Per run
one line: same or different, and where. Status and every other text column must be identical,
NaN where the other has NaN, and every numeric column equal within ``--rel`` (1e-9) of that
column's scale (its largest magnitude in DIR_A): the comparison for a restructuring that must
not change behaviour, where only the order of floating-point operations may differ. poses.csv
holds 9 significant digits, so two values a rounding step apart in the last printed digit also
count as equal (the file cannot tell them apart more finely); such cells are counted. Integer
columns (frame, marker counts) must be equal. Exit status 1 if any run differs, 2 on bad input.
"""

from __future__ import annotations

import argparse
import csv
import sys
from decimal import Decimal
from pathlib import Path

import numpy as np

POSES = "poses.csv"


def runs(folder: Path) -> dict[str, Path]:
    """Run name -> poses.csv of ``folder`` itself (name ".") or of each sub-folder."""
    if (folder / POSES).is_file():
        return {".": folder / POSES}
    return {p.parent.name: p for p in sorted(folder.glob(f"*/{POSES}"))}


def _read(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{path} is empty")
    return rows[0], rows[1:]


def _last_digit(cell: str) -> float:
    """The value of one unit in the last printed digit of a float cell; 0 for an integer or an
    exact zero (those must match exactly)."""
    value = float(cell)
    if not any(c in cell for c in ".eE") or value == 0.0 or not np.isfinite(value):
        return 0.0
    return float(Decimal(1).scaleb(Decimal(cell).as_tuple().exponent))


def compare(path_a: Path, path_b: Path, rel: float = 1e-9) -> tuple[bool, str]:
    """(same, one-line description) of two poses.csv files."""
    header_a, rows_a = _read(path_a)
    header_b, rows_b = _read(path_b)
    if header_a != header_b:
        return False, f"columns differ: {sorted(set(header_a) ^ set(header_b)) or 'order'}"
    if len(rows_a) != len(rows_b):
        return False, f"{len(rows_a)} rows against {len(rows_b)}"
    if any(len(r) != len(header_a) for r in rows_a + rows_b):
        return False, "a row has the wrong number of cells"
    text_a, text_b = np.array(rows_a, dtype=object), np.array(rows_b, dtype=object)
    worst, last_digit_only, problems = 0.0, 0, []
    for c, name in enumerate(header_a):
        col_a, col_b = text_a[:, c], text_b[:, c]
        try:
            a, b = col_a.astype(float), col_b.astype(float)
        except ValueError:  # a text column (status): identical
            bad = np.flatnonzero(col_a != col_b)
            if bad.size:
                problems.append(f"{name} row {bad[0]}: {col_a[bad[0]]!r} vs {col_b[bad[0]]!r}")
            continue
        nan_a, nan_b = np.isnan(a), np.isnan(b)
        bad = np.flatnonzero(nan_a != nan_b)
        if bad.size:
            problems.append(f"{name} row {bad[0]}: {col_a[bad[0]]} vs {col_b[bad[0]]} (NaN)")
            continue
        ok = ~nan_a
        scale = float(np.max(np.abs(a[ok]), initial=0.0))
        diff = np.where(ok, np.abs(a - b), 0.0)
        if scale > 0:
            worst = max(worst, float(diff.max(initial=0.0)) / scale)
        for i in np.flatnonzero(diff > rel * scale):
            unit = max(_last_digit(col_a[i]), _last_digit(col_b[i]))
            if diff[i] <= unit * (1 + 1e-9):  # adjacent printed values
                last_digit_only += 1
            else:
                problems.append(f"{name} row {i}: {col_a[i]} vs {col_b[i]} (scale {scale:.3g})")
                break
    if problems:
        return False, "; ".join(problems[:3]) + (f" (+{len(problems) - 3} columns)"
                                                 if len(problems) > 3 else "")  # fmt: skip
    note = (f"; {last_digit_only} cells one unit apart in the last printed digit"
            if last_digit_only else "")  # fmt: skip
    return True, (f"{len(rows_a)} rows, largest difference {worst:.1e} of a column's scale"
                  f" (tolerance {rel:g}){note}")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir_a", type=Path, help="the reference runs (e.g. before a change)")
    parser.add_argument("dir_b", type=Path, help="the runs to check against them")
    parser.add_argument("--rel", type=float, default=1e-9, help="tolerance relative to the "
                        "column's scale (default 1e-9)")  # fmt: skip
    args = parser.parse_args(argv)
    found = {}
    for folder in (args.dir_a, args.dir_b):
        found[folder] = runs(folder) if folder.is_dir() else {}
        if not found[folder]:
            print(f"error: no {POSES} in {folder} or its sub-folders; give two folders of runs",
                  file=sys.stderr)  # fmt: skip
            return 2
    a_runs, b_runs = found[args.dir_a], found[args.dir_b]
    all_same = True
    for name in sorted(a_runs.keys() | b_runs.keys()):
        if name not in b_runs or name not in a_runs:
            where = args.dir_b if name not in b_runs else args.dir_a
            print(f"{name}: DIFFERENT: no {POSES} in {where / name}")
            all_same = False
            continue
        try:
            same, text = compare(a_runs[name], b_runs[name], args.rel)
        except (OSError, ValueError, csv.Error) as err:
            same, text = False, f"unreadable: {err}"
        print(f"{name}: {'same' if same else 'DIFFERENT'}: {text}")
        all_same &= same
    return 0 if all_same else 1


if __name__ == "__main__":
    raise SystemExit(main())
