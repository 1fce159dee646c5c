"""The seed-spread section: its interval, its verdicts, and its figures against the robustness
table's for the same recordings."""

import numpy as np
import pytest

from benchmarks.accuracy import DEFAULT
from benchmarks.robustness import LEARNED, SMOOTHED, robustness
from benchmarks.seed_spread import mean_interval, seed_spread, spread_section


def test_the_interval_of_the_mean_matches_the_normal_theory_on_a_large_sample():
    v = np.random.default_rng(3).normal(0.6, 0.2, 400)
    lo, hi = mean_interval(v, level=0.9)
    half = 1.6449 * v.std(ddof=1) / np.sqrt(v.size)
    assert lo == pytest.approx(v.mean() - half, abs=0.15 * half)
    assert hi == pytest.approx(v.mean() + half, abs=0.15 * half)


def test_no_interval_from_too_few_seeds():
    assert np.isnan(mean_interval(np.array([0.5, 0.7]))).all()
    assert np.isnan(mean_interval(np.array([0.5, np.nan, np.nan, 0.7]))).all()


def _figures(rom_smoothed):
    n = len(rom_smoothed)
    return {
        "default/rot": np.full(n, 0.6), "default/pos": np.full(n, 1.1),
        "default/rom": np.full(n, 0.8), f"{SMOOTHED}/rom": np.array(rom_smoothed),
        "default/recall": np.full(n, 0.999), "default/cover": np.ones(n),
    }


def test_targets_are_judged_on_the_mean_and_the_seeds_that_miss_are_counted():
    seeds = tuple(range(4))
    summary, lines = spread_section(
        {"all (preset real)": _figures([0.9, 0.8, 0.3, 0.4]),  # seeds 0-2 miss; all four meet
         "all, left hand": _figures([0.9, 0.9, 0.8, 0.5])},
        seeds, table_seeds=3)
    assert summary[0] == "- all (preset real), over 4 seeds: meets every target."
    assert summary[1] == ("- all, left hand, over 4 seeds: misses worst RoM error, smoothed "
                          "(deg).")
    row = next(ln for ln in lines if ln.startswith("| all (preset real) | worst RoM error, sm"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    # target, mean, interval, seeds 0-2, best, median, worst, missing
    assert cells[2:] == ["<= 0.70", "0.60", cells[4], "0.67", "0.30", "0.60", "0.90", "2 of 4"]
    lo, hi = (float(x) for x in cells[4].split("-"))
    assert lo < 0.60 < hi


def test_each_seed_is_the_recording_the_robustness_table_averages(tmp_path):
    spread = seed_spread(tmp_path, (0, 1), n_frames=15, conditions=("all (preset real)",))
    table = robustness(tmp_path, (0, 1), n_frames=15, conditions=("all (preset real)",),
                       trackers={"default": DEFAULT})["all (preset real)"]
    figures = spread["all (preset real)"]
    for key, row, metric in (("default/rot", "default", "rot"),
                             (f"{SMOOTHED}/rom", SMOOTHED, "rom"),
                             ("default/recall", "default", "recall")):
        assert figures[key].shape == (2,)
        assert figures[key].mean() == pytest.approx(table[row][metric], rel=1e-9)
    assert figures[f"{LEARNED}/rom"].shape == (2,)


def test_learned_noise_table_sets_the_two_smoothers_side_by_side():
    model, learned = np.array([0.9, 0.5, 0.7]), np.array([0.6, 0.6, 0.4])
    spread = {"all (preset real)": {f"{SMOOTHED}/rom": model, f"{LEARNED}/rom": learned}}
    _, lines = spread_section(spread, (0, 1, 2))
    row = next(ln for ln in lines if ln.startswith("| all (preset real) | worst RoM error, sm")
               and ln.count("|") == 6)
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[2:] == ["0.70", "0.53", "2 of 3"]
    summary, _ = spread_section(spread, (0, 1, 2))
    assert summary[0].endswith("(`--smooth-noise learned`): worst RoM 0.70 -> 0.53.")
