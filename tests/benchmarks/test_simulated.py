"""The simulated section's tables are the same on every run of the same code."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from benchmarks import simulated
from wristtrack.sim.motion import scenario


def test_the_association_table_occludes_the_middle_of_each_seeds_own_recording(monkeypatch):
    # 'mix' drops frames at random: its length is the seed's, and the acceptance occlusion
    # (MCP4, MCP5 for 10 frames) belongs in the middle of the frames that seed has. Asked of
    # scenario() without the seed, the window moved between runs and so did the table.
    calls = []

    def fake_track_scenario(name, config, noise, seed):
        calls.append((name, seed, noise.occlusions[0][0]))
        errors = SimpleNamespace(orientation_rmse_deg=1.0, position_rmse_mm=1.0)
        return SimpleNamespace(errors=errors, labelling={"markers_correct": 1.0,
                                                         "clutter_as_marker": 0.0})

    monkeypatch.setattr(simulated, "track_scenario", fake_track_scenario)
    seeds = (0, 1, 2, 3)
    simulated.association_table(seeds)
    lengths = {s: len(scenario("mix", rng=np.random.default_rng(s))[0].t) for s in seeds}
    assert len(set(lengths.values())) > 1  # the seeds' recordings differ in length
    starts = {seed: start for name, seed, start in calls if name == "mix"}
    assert starts == {s: n // 2 - 5 for s, n in lengths.items()}
