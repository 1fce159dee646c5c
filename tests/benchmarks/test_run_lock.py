"""Two benchmark runs never share the render cache at once."""

import fcntl
import tempfile

from benchmarks import run


def test_a_second_run_on_a_busy_cache_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    cache = tmp_path / "wristtrack-bench"
    cache.mkdir()
    out = tmp_path / "B.md"
    with open(cache / ".lock", "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)  # the other run
        assert run.main(["--only", "step", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "another benchmark run is using" in err and "TMPDIR" in err and "\n" not in err
    assert not out.exists()
    # once the other run is done, the cache is free again
    with run._cache_lock(cache) as mine:
        assert mine
        with run._cache_lock(cache) as second:
            assert not second


def test_a_finished_run_leaves_its_lock_and_none_of_its_renders(tmp_path):
    """Every section renders afresh, so a run's recordings (~14 GB) are scratch afterwards."""
    cache = tmp_path / "wristtrack-bench"
    (cache / "robust-clean-0" / "rgb").mkdir(parents=True)
    (cache / "robust-clean-0" / "rgb" / "000000.png").write_bytes(b"png")
    (cache / "stray.csv").write_text("t\n")
    (cache / ".lock").write_text("")
    run.clear_renders(cache)
    assert [p.name for p in cache.iterdir()] == [".lock"]
