"""Fixtures shared by the whole suite: recordings rendered once per session, the contract
checker and the browser used by the page tests."""

from __future__ import annotations

import contextlib
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[2] / "shared"
CHROMIUM_INSTALL = "apt-get install chromium (Debian/Ubuntu; .ci/run does it in CI)"

# The interrupt tests send SIGINT (to this process and to `wristtrack` children). A shell
# without job control starts a background job (`make test &`) with SIGINT ignored, and an
# ignored signal stays ignored across exec: give it back its default meaning here (children
# then start with the default disposition too).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def rendered(tmp_path_factory) -> Callable[..., Path]:
    """``rendered(scenario, seed=0, **render_options)``: the folder of that simulated recording,
    rendered once per session and shared by every test asking for the same arguments.

    Read-only: a test that changes a recording copies it first (``shutil.copytree``).
    """
    from wristtrack.sim.render import render_recording

    root = tmp_path_factory.mktemp("rendered")
    cache: dict[tuple, Path] = {}

    def get(scenario: str, seed: int = 0, **options) -> Path:
        key = (scenario, seed, tuple(sorted((k, repr(v)) for k, v in options.items())))
        if key not in cache:
            folder = root / f"{len(cache):02d}-{scenario}-{seed}"
            cache[key] = Path(render_recording(folder, scenario, seed=seed, **options))
        return cache[key]

    return get


@pytest.fixture(scope="session")
def cut_recording() -> Callable[..., Path]:
    """``cut_recording(folder, frames, dest, hand=True, without_depth=())``: a recording folder
    cut to some of its frames (e.g. the ones a live run processed), without copying the images,
    optionally with some frames' depth left out (benchmarks.dropped.cut)."""
    from benchmarks.dropped import cut

    return cut


@pytest.fixture(scope="session")
def check_run() -> Path:
    """../shared/tools/check_run.py, the contract checker for a run folder."""
    path = SHARED / "tools" / "check_run.py"
    if not path.is_file():
        pytest.skip(f"the contract checker {path} is not beside the repository (../shared)")
    return path


@pytest.fixture(scope="session")
def chromium() -> str:
    """A headless-capable Chromium, or a skip that says how to install one."""
    for candidate in (shutil.which("chromium"), shutil.which("chromium-browser"),
                      "/usr/bin/chromium"):
        if candidate and Path(candidate).exists():
            return candidate
    pytest.skip(f"no Chromium for the browser check: install it with `{CHROMIUM_INSTALL}`")


def _interrupt_at(recording, index: int, nth: int = 1) -> None:
    """Make ``recording`` deliver a real SIGINT to this process as frame ``index`` is read for
    the ``nth`` time (a run without hand.json reads it in each of its two passes). The frames
    are read ahead of the run (io/prefetch.py): it stops at most a few frames before."""
    frames = recording.frames
    reads = [0]

    def interrupted(start=0):
        for frame in frames(start):
            if frame.index == index:
                reads[0] += 1
                if reads[0] == nth:
                    signal.raise_signal(signal.SIGINT)
            yield frame

    recording.frames = interrupted


@contextlib.contextmanager
def _briefly_primed(seconds: float = 0.3) -> Iterator[None]:
    from wristtrack.tracking import noise_scale

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(noise_scale, "PRIMING_S", seconds)
        yield


@pytest.fixture(scope="session")
def briefly_primed() -> Callable:
    """``with briefly_primed():`` track primes the noise over the first 0.3 s only, not 10 s.
    A run writes its first PRIMING_S once they have primed it, and a Ctrl-C stops it only
    after them (pipeline/priming.py): a test that interrupts a short recording part-way needs
    them short. In this process only (not in `wristtrack` children)."""
    return _briefly_primed


@pytest.fixture(scope="session")
def interrupt_at() -> Callable:
    """``interrupt_at(recording, index, nth=1)``: a real Ctrl-C as that frame is read (the nth
    time; see above)."""
    return _interrupt_at


@pytest.fixture(scope="session")
def every_effect(tmp_path_factory):
    """The 'mix' movement with every camera and hand effect at its realistic strength
    (benchmarks.robustness' "all (preset real)", seed 0), its first 136 frames. Read-only."""
    from benchmarks.robustness import render_condition

    return render_condition(tmp_path_factory.mktemp("every-effect"), "all (preset real)", 0, 136)


class HiddenMarkers:
    """The 'mix' movement (simulated detections, seed 1) with every blob gone over the frames
    ``hidden`` (a third of a second at 30 fps: a hand behind an obstacle)."""

    hidden = (70, 80)

    def run(self, config):
        """Track it with TrackerConfig ``config``: the truth, the results and the tracker."""
        import numpy as np

        from wristtrack.detect.detections import Detections
        from wristtrack.sim.detections import NoiseModel, simulate_detections
        from wristtrack.sim.motion import scenario
        from wristtrack.tracking.tracker import Tracker

        rng = np.random.default_rng(1)
        truth, camera, layout = scenario("mix", rng=rng)
        frames = simulate_detections(truth, camera, layout, NoiseModel(), rng)
        tracker = Tracker(camera, layout, config)
        results = []
        for k, f in enumerate(frames):
            det = f.detections
            if self.hidden[0] <= k < self.hidden[1]:
                det = Detections(det.timestamp, np.zeros((0, 2)), np.zeros(0))
            results.append(tracker.step(det))
        return truth, results, tracker


@pytest.fixture(scope="session")
def hidden_markers() -> HiddenMarkers:
    """Markers hidden for a third of a second mid-movement (:class:`HiddenMarkers`)."""
    return HiddenMarkers()
