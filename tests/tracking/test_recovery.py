"""Loss and recovery on simulated detections: the hand leaves the view and comes back; a filter
whose innovations stop being consistent is declared lost.

Oracles: the simulated ground truth, and the chi-square distribution of a consistent filter's
normalised innovation squared.
"""

import numpy as np
import pytest
from scipy.stats import chi2

from wristtrack.detect.detections import Detections
from wristtrack.geometry import so3_log
from wristtrack.hand import HandLayout
from wristtrack.sim.detections import NoiseModel, simulate_detections
from wristtrack.sim.motion import SCENARIOS, scenario
from wristtrack.sim.scenario_run import track_scenario
from wristtrack.tracking.tracker import Status, Tracker, TrackerConfig

FPS = 30.0
GONE = (60, 120)  # frames the hand is out of view: 2 s at 30 fps


def _run_with_absence(give_layout: bool, seed: int = 4):
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario("deviation", rng=rng)
    frames = simulate_detections(truth, camera, layout, NoiseModel(), rng)
    tracker = Tracker(camera, layout if give_layout else None, TrackerConfig())
    results, W0 = [], None
    for i, f in enumerate(frames):
        det = f.detections
        if GONE[0] <= i < GONE[1]:  # out of view: only clutter blobs remain
            n = rng.poisson(3.0)
            det = Detections(det.timestamp, rng.uniform([0, 0], [639, 479], (n, 2)),
                             rng.uniform(0.3, 2.0, n))
        results.append(tracker.step(det))
        if i == GONE[0] - 1:
            W0 = (tracker.R_c0.copy(), tracker.t_c0.copy())
    return truth, tracker, results, W0


@pytest.mark.parametrize("give_layout", [True, False], ids=["hand.json", "layout-from-depth"])
def test_hand_out_of_view_for_two_seconds_is_lost_then_found_again(give_layout):
    truth, tracker, results, W0 = _run_with_absence(give_layout)
    status = [r.status for r in results]
    lost_after = tracker.config.lost_after
    assert all(s == Status.TRACKING for s in status[: GONE[0]])

    # gone: a few frames of prediction while it is worth a pose (adding no more uncertainty to
    # the last update's than the coasting bounds, and near the truth), then no pose, no
    # extrapolation, not even where a clutter blob passed the widened gate; after lost_after
    # frames the track itself is lost
    gone = results[GONE[0] : GONE[1]]
    cfg, last = tracker.config, results[GONE[0] - 1]
    coasted = [r for r in gone[:lost_after] if r.status == Status.COASTING]
    assert 1 <= len(coasted) < lost_after
    assert all(r.status == Status.COASTING for r in gone[: len(coasted)])  # the first ones
    for k, r in enumerate(coasted, start=GONE[0]):
        assert r.rot_sigma_deg**2 - last.rot_sigma_deg**2 <= cfg.coast_rot_sigma_deg**2
        assert r.pos_sigma_mm**2 - last.pos_sigma_mm**2 <= cfg.coast_pos_sigma_mm**2
        assert np.linalg.norm(r.p - truth.p_rel[k]) < 3e-3 * r.pos_sigma_mm
    assert all(r.status == Status.LOST for r in gone[len(coasted) :])
    assert all(np.isnan(r.t_ch).all() and np.isnan(r.R).all() for r in gone[lost_after + 1 :])

    # back: tracking again within 10 frames, without the neutral pose
    back = next(i for i in range(GONE[1], len(results)) if status[i] == Status.TRACKING)
    assert back - GONE[1] < 10
    deviation = np.degrees(np.linalg.norm(so3_log(truth.R_rel[back])))
    assert deviation > 5.0, "the test must re-initialise away from the neutral pose"
    assert all(s == Status.TRACKING for s in status[back:])

    # W0 is still the first initialisation's, so poses stay comparable with truth's W0
    np.testing.assert_array_equal(tracker.R_c0, W0[0])
    np.testing.assert_array_equal(tracker.t_c0, W0[1])
    np.testing.assert_allclose(tracker.R_c0, truth.R_ch[0], atol=0.02)
    for i in range(back, len(results)):
        r = results[i]
        pos_err = np.linalg.norm(r.p - truth.p_rel[i])
        rot_err = np.degrees(np.linalg.norm(so3_log(r.R.T @ truth.R_rel[i])))
        assert pos_err < 0.006 and rot_err < 3.0, (i, pos_err, rot_err)


# ------------------------------------------------------------------- innovation consistency


def _longest_run(flags) -> int:
    best = run = 0
    for flag in flags:
        run = run + 1 if flag else 0
        best = max(best, run)
    return best


@pytest.mark.parametrize("name", SCENARIOS)
def test_innovation_check_never_fires_on_clean_scenarios(name):
    config = TrackerConfig()
    run = track_scenario(name, config, seed=7)  # acceptance noise: clutter, misses, occlusion
    assert run.lost_frames == 0
    assert not any(r.status == Status.LOST for r in run.results)
    updates = [r for r in run.results if r.nis_dof > 0]
    assert len(updates) > 0.95 * len(run.results)
    high = [r.nis > chi2.ppf(config.nis_quantile, r.nis_dof) for r in updates]
    # a consistent filter: rare exceedances, never a run long enough to lose the track
    assert np.mean(high) < 0.01
    assert _longest_run(high) < config.nis_lost_after


def _distorted_layout(layout: HandLayout, mm: float) -> HandLayout:
    """The hand the detections really come from: CMC1 and MCP5 moved apart by ``mm`` each, a
    change no rigid motion of the tracker's layout can explain."""
    pts = layout.points.copy()
    pts[1, 1] += mm / 1000
    pts[5, 1] -= mm / 1000
    return HandLayout(pts)


def _run_with_wrong_hand(config: TrackerConfig, start: int = 60):
    rng = np.random.default_rng(1)
    truth, camera, layout = scenario("deviation", rng=rng)
    noise = NoiseModel()
    right = simulate_detections(truth, camera, layout, noise, 2)
    # 4 mm each: within the association gate, far beyond the filter's noise. (Much more, and
    # the gate rejects CMC1 and MCP5 as clutter: the tracker follows the four that still fit.)
    wrong = simulate_detections(truth, camera, _distorted_layout(layout, 4.0), noise, 3)
    tracker = Tracker(camera, layout, config)
    return [
        tracker.step((wrong if i >= start else right)[i].detections) for i in range(len(right))
    ]


@pytest.mark.parametrize("use_depth", [True, False], ids=["fast-path", "generic-path"])
def test_inconsistent_innovations_lose_the_track(use_depth):
    start = 60
    results = _run_with_wrong_hand(TrackerConfig(use_depth=use_depth), start)
    status = [r.status for r in results]
    assert Status.LOST not in status[:start]
    first_lost = status.index(Status.LOST)
    assert start <= first_lost < start + 15
    # the markers were still being associated (the gate admitted them): the loss is the
    # innovation check's, not the too-few-markers rule's
    assert all(r.n_visible >= 4 for r in results[start:first_lost])
    limit = [chi2.ppf(0.999, r.nis_dof) for r in results[first_lost - 4 : first_lost]]
    assert all(r.nis > lim for r, lim in zip(results[first_lost - 4 : first_lost], limit,
                                             strict=True))


def test_without_the_innovation_check_the_wrong_hand_is_tracked_silently():
    # the same input with the check switched off: never lost, yet the NIS says it is wrong
    results = _run_with_wrong_hand(TrackerConfig(nis_lost_after=0))
    assert Status.LOST not in [r.status for r in results]
    late = [r for r in results[60:] if r.nis_dof]
    high = [r.nis > chi2.ppf(0.999, r.nis_dof) for r in late]
    assert np.mean(high) > 0.5


def test_the_paper_configuration_has_no_innovation_check():
    assert TrackerConfig.paper().nis_lost_after == 0
    assert TrackerConfig().nis_lost_after > 0
