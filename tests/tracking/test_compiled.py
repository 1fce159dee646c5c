"""The compiled tracker step (numba) against the generic step it stands in for, the reference:
same labels, the same state and covariance to rounding, and the generic path whenever numba
cannot load.

Tolerances come from the arithmetic: both steps compute the same float64 formulas in a
different order, so their results differ by a few hundred ulps of each quantity's scale, the
norm of the state or of the covariance matrix (an element much smaller than the norm carries
the rounding of the larger ones it was computed from), far below 1e-9 of that norm.
"""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristtrack import cli
from wristtrack.detect.detections import Detections
from wristtrack.sim.detections import acceptance_noise, simulate_detections
from wristtrack.sim.motion import scenario
from wristtrack.sim.scenario_run import track_scenario
from wristtrack.tracking import compiled
from wristtrack.tracking.models import ConstantRateModel
from wristtrack.tracking.tracker import Tracker, TrackerConfig, _Track

REL = 1e-9  # of the norm of the state / covariance


def _close(a: np.ndarray, b: np.ndarray, rel: float = REL) -> bool:
    return bool(np.linalg.norm(a - b) <= rel * np.linalg.norm(b))


@pytest.fixture(scope="module")
def step():
    kernel = compiled.load()
    assert kernel is not None, compiled.describe()  # numba is a dependency: it must compile
    return kernel


# a real Xtion's lens (../shared/realdata/README.md), and one with every term OpenCV has
XTION_LENS = (0.033, -0.108, 0.0, 0.0, 0.0)
RATIONAL_LENS = (0.08, -0.2, 1e-3, -2e-3, 0.05, 0.02, -0.01, 0.01)


# the states after the constant-rate model's: none, the skin slide (the default), the slide and
# the depth map's offset
STATES = {"rigid": TrackerConfig(follow_slide=False), "slide": TrackerConfig(),
          "offset": TrackerConfig(follow_offset=True)}


def _initialised_tracker(seed: int, states: str = "rigid", lens=None, delay=0.0) -> Tracker:
    """A tracker initialised on a simulated recording (W0 and the layout fixed); with the
    ``states`` (STATES) in its state, a camera with distortion ``lens`` whose depth frames are
    captured ``delay`` s after the colour."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario("deviation", rng=rng)
    camera = replace(camera, dist=lens, depth_delay=delay)
    frames = simulate_detections(truth, camera, layout, acceptance_noise(len(truth.t)), rng)
    tracker = Tracker(camera, layout, STATES[states])
    assert tracker.step(frames[0].detections).has_estimate
    return tracker


def _random_frame(rng, obs, turn=(0.0, 0.0, 0.0), states="rigid"):
    """A random state, covariance and interval, and blobs of markers near the prediction with
    misses, clutter and sometimes a blob crowding a marker (two markers then may want one).
    ``turn``: a rotation vector (W0 axes) the random orientation is drawn about; ``states``:
    what the state carries after the constant-rate model's (STATES: the skin slide,
    SlidingSkinModel's, a few mm; the depth offset, DepthOffsetModel's, a few px)."""
    scales = np.repeat([3e-4, 4e-6, 2.5e-3, 0.09], 3)  # rad^2, m^2, (m/s)^2, (rad/s)^2
    R = Rotation.from_rotvec(np.asarray(turn) + rng.normal(0, 0.3, 3)).as_matrix()
    x = ConstantRateModel.initial_state(
        R, rng.normal(0, 0.03, 3), rng.normal(0, 0.2, 3), rng.normal(0, 1.0, 3)
    )
    if states != "rigid":
        scales = np.concatenate((scales, [2e-6, 3e-7]))  # m^2, distal and lateral
        x = np.concatenate((x, rng.normal(0, [1.5e-3, 5e-4])))
    if states == "offset":
        scales = np.concatenate((scales, [2.0, 2.0]))  # px^2
        x = np.concatenate((x, rng.normal(0, 1.5, 2)))
    n = scales.size
    A = rng.standard_normal((n, n)) * np.sqrt(scales / n)[:, None] * rng.uniform(0.1, 3)
    P = A @ A.T + np.diag(scales) * 0.05
    dt = rng.uniform(0.01, 0.07)
    moved = x.copy()
    moved[9:12] += x[12:15] * dt
    y = obs(moved[None]).reshape(6, 3)
    seen = y[rng.random(6) > 0.15] + rng.normal(0, 1, (1, 3)) * [2.0, 2.0, 3e-3]
    cam = obs.camera
    clutter = rng.uniform([0, 0, 0.3], [cam.width, cam.height, 2.0], (rng.poisson(3), 3))
    if rng.random() < 0.3:
        clutter = np.vstack((clutter, y[rng.integers(6)] + rng.normal(0, 1, 3) * [3, 3, 3e-3]))
    z = np.vstack((seen, clutter))
    z = z[rng.permutation(len(z))]
    suspect = rng.random(len(z)) < 0.3
    return Detections(1.0, z[:, :2].copy(), z[:, 2].copy(), suspect=suspect), x, P, dt


def _blob_var(obs, det: Detections) -> np.ndarray:
    """The step's per-blob pixel variance, as the tracker passes it."""
    return obs.blob_variance(det.suspect, det.count)


@pytest.mark.parametrize(("states", "lens", "delay"), [
    ("rigid", None, 0.0), ("slide", None, 0.0), ("offset", None, 0.0),
    ("rigid", XTION_LENS, 0.0), ("offset", RATIONAL_LENS, 0.0), ("slide", None, 0.012),
    ("offset", XTION_LENS, -0.016),
])  # fmt: skip
def test_compiled_step_equals_the_generic_step_on_400_random_frames(step, states, lens, delay):
    """Suspect blobs among them, taken at the model's pixel sigma above a learned one; with
    and without the skin slide (its spread learned to half the model's) and the depth offset
    in the state, lens distortion, and depth captured after or before the colour."""
    tracker = _initialised_tracker(seed=7, states=states, lens=lens, delay=delay)
    if states != "rigid":
        tracker.model.slide_scale = 0.5
    obs = tracker._observation(True)
    obs.set_pixel_sigma(0.1)
    assert obs.suspect_variance == pytest.approx(0.3**2 - 0.1**2)
    cfg = tracker.config
    args = compiled.frame_constants(tracker.model, obs, cfg.ukf, cfg.facing_cos,
                                    tracker.assoc_params)  # fmt: skip
    rng = np.random.default_rng(8)
    outcomes = {compiled.OK: 0, compiled.DECLINED: 0}
    for _ in range(400):
        det, x, P, dt = _random_frame(rng, obs, states=states)
        code, x_c, P_c, labels, n_pairs, nis = step(x, P, dt, det.uv, det.depth,
                                                     _blob_var(obs, det), *args)
        outcomes[code] += 1
        x_g, P_g, labels_g, n_g, nis_g, dof_g, merged_g = tracker._generic_frame(
            det, _Track(x, P, 0.0), dt)
        if code == compiled.DECLINED:
            continue
        np.testing.assert_array_equal(labels, labels_g)
        assert merged_g == {}  # the step takes no frame where markers may have merged
        assert n_pairs == n_g and 3 * n_pairs == dof_g
        assert _close(x_c, x_g), np.linalg.norm(x_c - x_g) / np.linalg.norm(x_g)
        assert _close(P_c, P_g), np.linalg.norm(P_c - P_g) / np.linalg.norm(P_g)
        if n_pairs:
            assert nis == pytest.approx(nis_g, rel=REL)
        else:
            assert np.isnan(nis) and np.isnan(nis_g)
    # both outcomes exercised: most frames compiled, clashing markers declined to the solver
    assert outcomes[compiled.OK] > 250 and outcomes[compiled.DECLINED] > 20


def test_compiled_step_equals_the_generic_step_with_the_hand_turned_edge_on(step):
    """The back of the hand turned 60-80 deg from the line of sight: the markers' depth noise
    grows as Nguyen et al. measured (depth_noise.oblique_sigma), in both paths alike."""
    tracker = _initialised_tracker(seed=7)
    obs = tracker._observation(True)
    cfg = tracker.config
    args = compiled.frame_constants(tracker.model, obs, cfg.ukf, cfg.facing_cos,
                                    tracker.assoc_params)  # fmt: skip
    rng = np.random.default_rng(9)
    oblique = 0
    for _ in range(150):
        det, x, P, dt = _random_frame(rng, obs, turn=(0.0, 1.2, 0.0))
        code, x_c, P_c, labels, n_pairs, nis = step(x, P, dt, det.uv, det.depth,
                                                     _blob_var(obs, det), *args)
        x_g, P_g, labels_g, n_g, nis_g, dof_g, _ = tracker._generic_frame(
            det, _Track(x, P, 0.0), dt)
        if code == compiled.DECLINED or n_pairs == 0:
            continue
        z = obs(x[None])[0].reshape(6, 3)[:, 2]
        facing_sd = obs.noise.depth_sigma(z)
        oblique += np.any(np.sqrt(obs.noise_variance(x, obs(x[None])[0])[2::3]) > facing_sd)
        np.testing.assert_array_equal(labels, labels_g)
        assert _close(x_c, x_g) and _close(P_c, P_g)
        assert nis == pytest.approx(nis_g, rel=REL)
    assert oblique > 40  # frames updated with some marker seen beyond 60 deg


def test_compiled_step_declines_what_only_the_generic_path_handles(step):
    tracker = _initialised_tracker(seed=3)
    obs, cfg = tracker._observation(True), tracker.config
    args = compiled.frame_constants(tracker.model, obs, cfg.ukf, cfg.facing_cos,
                                    tracker.assoc_params)  # fmt: skip
    rng = np.random.default_rng(4)
    while True:  # a frame the step takes
        det, x, P, dt = _random_frame(rng, obs)
        if step(x, P, dt, det.uv, det.depth, _blob_var(obs, det), *args)[0] == compiled.OK:
            break
    indefinite = P.copy()
    indefinite[4, 4] = -1e-3  # the generic path repairs it (safe_cholesky); the step declines
    blob_var = _blob_var(obs, det)
    assert step(x, indefinite, dt, det.uv, det.depth, blob_var, *args)[0] == compiled.DECLINED
    away = x.copy()
    away[:9] = Rotation.from_rotvec([np.pi, 0, 0]).as_matrix().reshape(9)  # palm turned away
    assert step(away, P, dt, det.uv, det.depth, blob_var, *args)[0] == compiled.DECLINED
    uv = det.uv.copy()
    uv[0] = np.nan
    assert step(x, P, dt, uv, det.depth, blob_var, *args)[0] == compiled.DECLINED
    # what the tracker returns for a declined frame is the generic path's, unchanged
    track = _Track(x, indefinite, 0.0)
    assert tracker._compiled_frame(det, track, dt) is None
    # blobs that are views into a wider array reach the step as contiguous copies
    wide = np.column_stack((det.uv, det.depth))
    strided = Detections(1.0, wide[:, :2], wide[:, 2])
    assert not strided.uv.flags.c_contiguous
    a = tracker._compiled_frame(strided, _Track(x, P, 0.0), dt)
    b = tracker._compiled_frame(det, _Track(x, P, 0.0), dt)
    np.testing.assert_array_equal(a[2], b[2])
    np.testing.assert_array_equal(a[0], b[0])


def _assert_same_results(first, second) -> None:
    for a, b in zip(first, second, strict=True):
        assert a.status == b.status
        np.testing.assert_array_equal(a.labels, b.labels)
        if a.has_estimate:
            assert _close(a.x, b.x) and _close(a.cov, b.cov)
            assert _close(a.t_ch, b.t_ch) and _close(a.R_ch, b.R_ch)
            assert a.nis_dof == b.nis_dof
            assert a.nis == pytest.approx(b.nis, rel=REL, nan_ok=True)


def _tracked(name: str, config: TrackerConfig, lens=None, seed: int = 2, delay=0.0,
             readout=None) -> list:
    """Track scenario ``name`` (acceptance noise) as seen through a lens with distortion
    ``lens`` (None: a pinhole), depth captured ``delay`` s after the colour; ``"stamped"``:
    each frame's own delay (Detections.depth_delay), within +-16 ms, changing every frame; a
    rolling shutter reading its rows in ``readout`` s."""
    rng = np.random.default_rng(seed)
    truth, camera, layout = scenario(name, rng=rng)
    camera = replace(camera, dist=lens, depth_delay=None if delay == "stamped" else delay,
                     readout=readout)
    frames = simulate_detections(truth, camera, layout, acceptance_noise(len(truth.t)), rng)
    tracker = Tracker(camera, layout, config)
    if delay == "stamped":
        return [tracker.step(replace(f.detections, depth_delay=0.016 * math.sin(k)))
                for k, f in enumerate(frames)]
    return [tracker.step(f.detections) for f in frames]


@pytest.mark.parametrize(("name", "states", "lens", "delay", "readout"), [
    ("pronation", "rigid", None, 0.0, None), ("mix", "rigid", None, 0.0, None),
    ("mix", "slide", None, 0.0, None), ("mix", "offset", None, 0.0, None),
    ("mix", "rigid", XTION_LENS, 0.0, None), ("pronation", "offset", XTION_LENS, 0.0, None),
    ("mix", "slide", None, 0.014, None), ("mix", "slide", None, "stamped", None),
    ("mix", "slide", XTION_LENS, 0.0, 0.025), ("mix", "offset", None, -0.01, 0.03),
])  # fmt: skip
def test_tracker_compiled_path_matches_the_generic_path(monkeypatch, step, name, states, lens,
                                                        delay, readout):
    """Acceptance noise: clutter, misses, an occlusion, irregular frame intervals; with the
    skin slide in the state, its spread learned as the track goes; through a real lens; a depth
    delay; a rolling shutter."""
    taken = []
    compiled_frame = Tracker._compiled_frame

    def counted(self, *args):
        out = compiled_frame(self, *args)
        taken.append(out is not None)
        return out

    monkeypatch.setattr(Tracker, "_compiled_frame", counted)
    config = STATES[states]
    fast = _tracked(name, config, lens, delay=delay, readout=readout)
    assert sum(taken) > 0.9 * len(taken)  # the compiled step took nearly every frame
    monkeypatch.setattr(Tracker, "_compiled_frame", lambda self, det, track, dt: None)
    generic = _tracked(name, config, lens, delay=delay, readout=readout)
    _assert_same_results(fast, generic)


def _without_numba(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "numba", None)  # import numba now fails
    monkeypatch.setattr(compiled, "_loaded", None)  # as in a fresh process


def test_without_numba_the_generic_path_runs_and_version_says_so(monkeypatch, capsys, step):
    reference = track_scenario("deviation", TrackerConfig(), seed=1)
    _without_numba(monkeypatch)
    assert compiled.load() is None
    assert compiled.describe().startswith("generic NumPy reference (numba not available:")
    generic_frames = []
    generic = Tracker._generic_frame

    def counted(self, *args):
        generic_frames.append(1)
        return generic(self, *args)

    monkeypatch.setattr(Tracker, "_generic_frame", counted)
    run = track_scenario("deviation", TrackerConfig(), seed=1)
    tracked = sum(r.status != "initialising" for r in run.results[1:])
    assert len(generic_frames) >= tracked > 0
    _assert_same_results(run.results, reference.results)
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--version"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "tracker step: generic NumPy reference (numba not available" in out


def test_a_numba_that_cannot_compile_gives_the_generic_path(monkeypatch):
    def broken(numba):
        raise TypeError("unsupported\nsecond line")

    monkeypatch.setattr(compiled, "_jit", broken)
    monkeypatch.setattr(compiled, "_loaded", None)
    assert compiled.load() is None
    assert "could not compile the step: TypeError: unsupported)" in compiled.describe()
    tracker = _initialised_tracker(seed=3)
    det = Detections(2.0, np.array([[320.0, 240.0]]), np.array([0.6]))
    assert tracker._compiled_frame(det, tracker._track, 0.03) is None


def test_version_names_the_compiled_step(capsys, step):
    with pytest.raises(SystemExit):
        cli.main(["--version"])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("wristtrack ")
    assert lines[1] == f"tracker step: compiled (numba {sys.modules['numba'].__version__})"


def test_importing_wristtrack_and_the_tracker_does_not_import_numba():
    code = (
        "import sys, wristtrack; from wristtrack.tracking.tracker import Tracker; "
        "sys.exit('numba' in sys.modules)"
    )
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_the_tracker_calls_the_step_with_the_types_it_was_compiled_for(step):
    track_scenario("mix", TrackerConfig(), seed=2)
    assert len(step.signatures) == 1  # no second compile in the first frames of a real run


def test_the_cache_key_changes_with_the_code_compiled_into_the_step():
    def a(x):
        return 2.0 * x

    def b(x):
        return 3.0 * x

    def a_again(x):
        return 2.0 * x

    digest = compiled._code_digest
    assert digest([a]) == digest([a_again]) != digest([b])
    assert digest([a, b]) != digest([b, a])


def test_a_pickled_tracker_comes_back_with_its_compiled_step(step):
    import pickle

    rng = np.random.default_rng(5)
    truth, camera, layout = scenario("pronation", rng=rng)
    frames = simulate_detections(truth, camera, layout, acceptance_noise(len(truth.t)), rng)
    tracker = Tracker(camera, layout, TrackerConfig())
    for f in frames[:20]:
        tracker.step(f.detections)
    assert tracker._compiled is not None
    restored = pickle.loads(pickle.dumps(tracker))
    a = [tracker.step(f.detections) for f in frames[20:40]]
    b = [restored.step(f.detections) for f in frames[20:40]]
    assert restored._compiled is not None and restored._compiled[0] is step
    for ra, rb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ra.x, rb.x)
        np.testing.assert_array_equal(ra.labels, rb.labels)
