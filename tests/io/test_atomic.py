"""io.atomic: a file is replaced whole or not at all, with no temporary file left behind."""

import json
import os
import stat

import pytest

from wristtrack.io.atomic import atomic_path, write_bytes_atomic, write_json_atomic


def test_replaces_whole_with_the_mode_of_a_plain_file(tmp_path):
    target = tmp_path / "a.bin"
    target.write_bytes(b"old")
    write_bytes_atomic(target, b"new", durable=True)
    assert target.read_bytes() == b"new"
    plain = tmp_path / "plain"
    plain.write_bytes(b"")
    assert stat.S_IMODE(target.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
    assert sorted(os.listdir(tmp_path)) == ["a.bin", "plain"]


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "summary.json"
    write_json_atomic(target, {"a": 1})
    with pytest.raises(ValueError):  # NaN is not JSON: refused before anything is replaced
        write_json_atomic(target, {"a": float("nan")})
    assert json.loads(target.read_text()) == {"a": 1}
    with pytest.raises(RuntimeError), atomic_path(target, suffix=".tmp.c3d") as tmp:
        assert tmp.name.endswith(".tmp.c3d") and tmp.parent == tmp_path
        tmp.write_text("half")
        raise RuntimeError("writer failed")
    assert json.loads(target.read_text()) == {"a": 1}
    assert os.listdir(tmp_path) == ["summary.json"]


def test_two_writers_of_one_target_use_their_own_temporaries(tmp_path):
    target = tmp_path / "x.txt"
    with atomic_path(target) as first, atomic_path(target) as second:
        assert first != second
        first.write_text("first")
        second.write_text("second")
    assert target.read_text() == "first"  # the outer block ends last: its file wins
    assert os.listdir(tmp_path) == ["x.txt"]
