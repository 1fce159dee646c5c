"""The tracker's settings: motion and measurement models, association, loss and recovery."""

from __future__ import annotations

import math
from dataclasses import dataclass

from wristtrack.filter import associate as assoc
from wristtrack.filter import ukf
from wristtrack.tracking.models import MODELS, ProcessNoise
from wristtrack.tracking.observation import MeasurementNoise
from wristtrack.tracking.offset_model import DepthOffsetModel
from wristtrack.tracking.slide_model import SlidingSkinModel
from wristtrack.tracking.surface import SurfaceSettings

SMOOTHING_NOISE = ("learned", "model")  # TrackerConfig.smoothing_noise


@dataclass(frozen=True)
class TrackerConfig:
    model: str = "default"  # "default" (SO(3) error state, constant rate) or "paper"
    association: str = "gnn"  # "gnn", "jpda" or "paper"
    use_depth: bool = True  # depth of each marker in every update (when the frame has depth)
    # The skin between the markers as depth patches, learned over the still start and used in
    # every update with depth (tracking/surface.py); None: the markers' depth alone.
    surface: SurfaceSettings | None = SurfaceSettings()
    measurement: MeasurementNoise = MeasurementNoise()
    # Scale the modelled skin slide by how much the recording shows, and take the blobs' pixel
    # noise from it (tracking/noise_scale.py, pixel_noise.py); False: the model's throughout.
    adapt_slide: bool = True
    adapt_pixel: bool = True
    # Offline, what is learned is primed: a first pass over the recording's first seconds
    # learns it, and the run starts from there (pipeline/priming.py, noise_scale.PRIMING_S)
    # rather than from the model's noise, which left a recording's still start and first
    # movement to the depth and to a long shutter's blur. A live camera cannot be read twice:
    # it learns from its first frame on, as with False.
    prime_noise: bool = True
    # The default model with the MCP markers' skin slide along the hand (distal, lateral) in its
    # state (tracking/slide_model.py); False: the slide as noise the markers share afresh each
    # frame, where a hand turned edge-on took part of it as a tilt (docs/BENCHMARKS.md, spread).
    follow_slide: bool = True
    # With the slide in the state and depth in the updates: the depth map's offset from the
    # colour image (a calibration error of 1-2 px) in the state too (tracking/offset_model.py);
    # False: as noise the markers and the skin share afresh each frame. Off by default: it
    # halves the position error of structured light alone, but under every effect at once its
    # estimate takes up the hand's own depth errors and the left hands' range of motion came
    # out worse (10 rendered seeds: 0.95 -> 1.02 deg; tracking/offset_model.py).
    follow_offset: bool = False
    process: ProcessNoise = ProcessNoise()
    # ``track --smooth``: "model" smooths the run at ``process`` as it is; "learned" tracks the
    # recording once more at the angular process noise its smoothed rates show, then smooths
    # that run (pipeline/refit.py, tracking/smoother_noise.py). Not the default: better on slow,
    # smooth rendered movements under every camera effect, worse on real recorded motions,
    # whose fast detail the first smoothed run's rates miss (docs/BENCHMARKS.md).
    smoothing_noise: str = "model"
    association_params: assoc.AssociationParams = assoc.AssociationParams()
    ukf: ukf.UKFParams = ukf.UKFParams()
    min_markers: int = 3  # fewer associated markers than this counts towards being lost
    lost_after: int = 15  # consecutive such frames before declaring the track lost
    # A frame with fewer than min_markers markers (none: coasting) reports its pose only while
    # the uncertainty added since the last frame with enough stays within these 1-sigma bounds
    # (rot_sigma_deg, pos_sigma_mm of poses.csv, in quadrature); beyond them it reports no pose
    # (lost), while the track goes on predicting to take the markers back when they return. A
    # single marker may be clutter the wide gate let in, and an extrapolated turn is soon
    # worth nothing: half a second without markers put a slow rendered movement 33 deg off
    # (sigma 33), the real racing glove at full speed 1.2 m off (sigma 0.12 m).
    coast_rot_sigma_deg: float = 2.0
    coast_pos_sigma_mm: float = 10.0
    max_gap: float = 0.5  # s; a longer gap between frames loses the track
    facing_cos: float = 0.05  # a marker whose palm faces away more than this is not expected
    # Innovation consistency: an update whose NIS exceeds this chi-square quantile is
    # inconsistent; this many in a row lose the track (0 = never). A consistent filter sees
    # such a run with probability (1 - quantile)^n, ~1e-15 here.
    nis_quantile: float = 0.999
    nis_lost_after: int = 5
    # Manoeuvres: a frame whose association fails (fewer than min_markers markers, or an
    # update beyond the NIS quantile) although enough undoubted blobs (min_markers, none
    # suspect: Tracker._undoubted) are there is associated again with the prior's velocity
    # variances raised by (a dt)^2, (alpha dt)^2 for each (a m/s^2, alpha rad/s^2) in turn: an
    # unmodelled acceleration (a fast reach peaks at ~15 m/s^2). A retry is kept only if its
    # update is consistent. () = off (the paper's method).
    manoeuvre_accel: tuple[tuple[float, float], ...] = ((15.0, 15.0), (45.0, 45.0))
    # A frame still short of min_markers markers (after the retry) among enough blobs, or
    # whose inconsistent or retried update left the markers off their blobs, is fitted afresh,
    # as an initialisation would (Tracker._reacquire). False: the paper's way.
    reacquire: bool = True
    # After a gap (a step over tracker.LONG_GAP_S: frames dropped) the prediction may be far
    # off, and one unscented correction stops short: the update is iterated this many times
    # over its posterior (ukf.iterated_update). 0: one update, the paper's way.
    gap_iterations: int = 2
    # A blob where two or three markers seen close together merged is taken as the mean of
    # their centres (tracking/merged.py), with one-to-one association. False: as the one marker
    # the association gave it to, the paper's way.
    merged_blobs: bool = True

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"unknown model {self.model!r}; choose one of {', '.join(MODELS)}")
        if self.association not in assoc.METHODS:
            raise ValueError(
                f"unknown association {self.association!r}; choose one of "
                f"{', '.join(assoc.METHODS)}"
            )
        if self.smoothing_noise not in SMOOTHING_NOISE:
            raise ValueError(f"unknown smoothing noise {self.smoothing_noise!r}; choose one of "
                             f"{', '.join(SMOOTHING_NOISE)}")
        if self.gap_iterations < 0:
            raise ValueError(f"gap_iterations must be 0 or more, got {self.gap_iterations}")

    @property
    def learns_pixel_noise(self) -> bool:
        """Whether the tracker learns the blobs' pixel noise: with one-to-one association only,
        whose update the estimate reads (JPDA's mixes blobs; on the measurement-level `mix`
        recordings learning with it cost 0.95 -> 2.76 deg)."""
        return self.adapt_pixel and self.association == "gnn"

    @property
    def primes_noise(self) -> bool:
        """Whether an offline run primes what the tracker learns: ``prime_noise``, where the
        tracker learns anything."""
        return self.prime_noise and (self.adapt_slide or self.learns_pixel_noise)

    def make_model(self):
        """The state model these settings name: the default model with the skin slide in its
        state where ``follow_slide`` (and a slide is modelled), and with the depth offset too
        where ``follow_offset`` (with depth, and a misregistration modelled), else
        MODELS[model]."""
        if self.model == "default" and self.follow_slide and any(self.measurement.skin_slide):
            noise = self.measurement
            if self.follow_offset and self.use_depth and noise.registration_px > 0:
                return DepthOffsetModel(self.process, noise.skin_slide,
                                        prior_px=noise.registration_px)
            return SlidingSkinModel(self.process, noise.skin_slide)
        return MODELS[self.model](self.process)

    @property
    def skin_depth(self) -> bool:
        """Whether the tracker learns the skin between the markers and reads its depth."""
        return self.surface is not None and self.use_depth

    @property
    def coast_limit(self) -> tuple[float, float]:
        """(coast_rot_sigma_deg, coast_pos_sigma_mm): what a frame without enough markers may
        add to the last measured frame's 1-sigma and still report a pose (also when smoothed)."""
        return self.coast_rot_sigma_deg, self.coast_pos_sigma_mm

    @classmethod
    def paper(cls, **kw) -> TrackerConfig:
        """The paper's method: Euler-angle state, per-blob association, depth only to initialise.

        No innovation-consistency loss: the paper has none (and its filter is not consistent).
        No noise shared between markers (skin slide, misregistration): the paper models its
        blobs as independent, at the 0.7 px our own filter used before it modelled them, fixed.
        No depth of the skin between the markers. Every prediction is reported (no coasting
        bounds): the paper coasts on the model through occlusions.
        """
        kw.setdefault("measurement", MeasurementNoise(pixel_sigma=0.7, skin_slide=(0.0, 0.0, 0.0),
                                                      registration_px=0.0))
        kw.setdefault("nis_lost_after", 0)
        kw.setdefault("manoeuvre_accel", ())
        kw.setdefault("reacquire", False)
        kw.setdefault("gap_iterations", 0)
        kw.setdefault("merged_blobs", False)
        kw.setdefault("adapt_pixel", False)
        kw.setdefault("prime_noise", False)  # nothing to prime: no slide, no pixel noise learned
        kw.setdefault("surface", None)
        kw.setdefault("coast_rot_sigma_deg", math.inf)
        kw.setdefault("coast_pos_sigma_mm", math.inf)
        kw.setdefault("model", "paper")  # or "paper_rpy": roll-pitch-yaw angles
        return cls(association="paper", use_depth=False, **kw)
