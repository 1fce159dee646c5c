"""A frame the update cannot explain, tried again under what the filter's model left out.

A frame whose update associates too few markers, or whose markers' normalised innovation
squared (NIS) is beyond its chi-square bound, although enough undoubted blobs are there, is
re-associated and updated again under each of these in turn; the first retry that associates
at least as many markers (and at least ``min_markers``) with a consistent update is kept, else
the plain update:

- **a long shutter's blur** (:func:`long_shutter`): the blobs' pixel noise grows with their
  image speed at the rate the frames' fit residuals show (tracking/pixel_noise.py), and a
  movement's first frames, slow (up to 1-2 px per frame), show the residuals no growth under a
  1/30 s shutter either. On a still start and one reach so rendered, the spread had learned
  no growth by the time the fast frames came, and they were updated at the sharp blobs' sigma
  (their centre errors: 0.02 px per coordinate at rest, 0.1-0.15 at 7-11 px per frame): NIS 48
  and 62 on 18 degrees of freedom, 1.9 deg on the pronation axis, which did not move. Retried
  with the prior's growth beyond the speeds learned from (BlobSpread.growth), the frame is
  explained (5 seeds: orientation 0.254 -> 0.211 deg, worst range-of-motion error 1.48 ->
  1.04). Only where the update has failed: every frame beyond those speeds taken so handed a
  sharp camera's first fast frames to the depth (structured light, 8 seeds: 0.240 -> 0.270 deg;
  clean 0.135 -> 0.149); there no update fails, and the retry is never tried;
- **a manoeuvre** (:func:`manoeuvre`, TrackerConfig.manoeuvre_accel): the prior's velocity
  variances raised by (a dt)^2 for an unmodelled acceleration a.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from itertools import chain
from typing import Any

import numpy as np

from wristtrack.detect.detections import Detections
from wristtrack.filter.ukf import chi2_quantile


def retried(tracker: Any, det: Detections, track: Any, dt: float, out: tuple) -> tuple:
    """``out`` (Tracker._filter_frame's result for the detections ``det`` from the tracker's
    ``track``, ``dt`` s on), or the first retry that explains the frame (module doc). The
    tracker and its track are typed Any, as in tracking/hypotheses.py: the tracker imports this
    module."""
    cfg = tracker.config
    n_assoc, nis, dof = out[3], out[4], out[5]
    if n_assoc >= cfg.min_markers and not (dof and nis > chi2_quantile(cfg.nis_quantile, dof)):
        return out
    # lazily: a retry that explains the frame spares the later ones their update
    for retry in chain(long_shutter(tracker, det, track, dt), manoeuvre(tracker, det, track, dt)):
        n, r_nis, r_dof = retry[3], retry[4], retry[5]
        if n >= max(cfg.min_markers, n_assoc) and r_nis <= chi2_quantile(cfg.nis_quantile, r_dof):
            return retry
    return out


def long_shutter(tracker: Any, det: Detections, track: Any, dt: float) -> Iterator[tuple]:
    """The frame updated with a long shutter's blur beyond the speeds the blobs' spread was
    learned at (noise_scale.LearnedNoise.long_shutter_variance); nothing where that adds no
    noise."""
    observations = list(tracker._obs.values())
    variances = [tracker.learned_noise.long_shutter_variance(o) for o in observations]
    if all(v is None for v in variances):
        return
    with _blur_taken(observations, variances):
        result = tracker._filter_frame(det, track, dt)
    yield result


def manoeuvre(tracker: Any, det: Detections, track: Any, dt: float) -> Iterator[tuple]:
    """The frame updated with the prior's velocity variances raised by (a dt)^2, (alpha dt)^2
    for each (a m/s^2, alpha rad/s^2) of TrackerConfig.manoeuvre_accel in turn."""
    model = tracker.model
    for accel, angular in tracker.config.manoeuvre_accel:
        P = track.P.copy()
        for part, a in ((model.velocity, accel), (model.angular_velocity, angular)):
            i = np.arange(P.shape[0])[part]
            P[i, i] += (a * dt) ** 2
        yield tracker._filter_frame(det, replace(track, P=P), dt)


@contextmanager
def _blur_taken(observations: list, variances: list) -> Iterator[None]:
    """The MarkerObservations taking the blur variances given (None: theirs), theirs after."""
    kept = [o.motion_variance for o in observations]
    try:
        for o, v in zip(observations, variances, strict=True):
            if v is not None:
                o.motion_variance = v
        yield
    finally:
        for o, v in zip(observations, kept, strict=True):
            o.motion_variance = v
