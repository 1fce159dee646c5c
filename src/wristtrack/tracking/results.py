"""What the tracker says about one frame: its status and, where it has one, the estimate."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np


class Status(StrEnum):
    INITIALISING = "initialising"  # no estimate yet: waiting for all six markers
    TRACKING = "tracking"  # estimate updated with this frame's markers
    COASTING = "coasting"  # estimate predicted only: no marker associated in this frame
    LOST = "lost"  # too long without enough markers, or innovations inconsistent: no estimate


_NAN3 = np.full(3, np.nan)
_NAN33 = np.full((3, 3), np.nan)
_NAN3.setflags(write=False)  # shared by every result without an estimate
_NAN33.setflags(write=False)


@dataclass(frozen=True)
class FrameResult:
    """The estimate for one frame. Poses are NaN where ``status`` has no estimate."""

    frame: int
    timestamp: float
    status: Status
    R_ch: np.ndarray  # (3,3) hand -> camera
    t_ch: np.ndarray  # (3,) wrist in camera coordinates, m
    R: np.ndarray  # (3,3) hand relative to W0
    p: np.ndarray  # (3,) wrist in W0, m
    v: np.ndarray  # (3,) m/s in W0
    w: np.ndarray  # (3,) rad/s in W0
    cov: np.ndarray | None  # tangent covariance of the state
    labels: np.ndarray  # (M,) marker index per blob, -1 = clutter
    n_visible: int  # markers measured in this frame (each of a merged blob's: ``merged``)
    n_clutter: int  # blobs taken as clutter
    nis: float = np.nan  # normalised innovation squared of the update
    nis_dof: int = 0
    pos_sigma_mm: float = np.nan  # 1-sigma position uncertainty (root of the variance trace)
    rot_sigma_deg: float = np.nan  # 1-sigma orientation uncertainty
    x: np.ndarray | None = None  # the filter state (model.initial_state layout); for smoothing
    # one continuous filter state: a new id at each initialisation and where the still start
    # moves W0 (tracking/neutral.py); the smoother never smooths across two ids
    track_id: int = -1
    side: str = "right"  # the hand's side (from its layout): signs of the anatomical angles
    # blob -> the markers (its label's among them) whose mean the blob measured: where markers
    # seen close together merged into one blob (tracking/merged.py); empty in most frames
    merged: dict[int, tuple[int, ...]] = field(default_factory=dict)

    @property
    def has_estimate(self) -> bool:
        return self.status in (Status.TRACKING, Status.COASTING)

    @classmethod
    def empty(
        cls,
        frame: int,
        timestamp: float,
        status: Status,
        labels: np.ndarray | int = 0,
        n_visible: int = 0,
        **kw,
    ) -> FrameResult:
        """A result without an estimate (NaN poses; no covariance unless given). ``labels`` are
        the blobs' labels, or a number of blobs, all then clutter; ``n_clutter`` defaults to the
        blobs labelled clutter. Other fields (``side``, ``track_id``, a state ``x`` and ``cov``
        the smoother may use, ...) by keyword."""
        if np.ndim(labels) == 0:
            labels = np.full(int(labels), -1)
        kw.setdefault("n_clutter", int(np.sum(labels < 0)))
        kw.setdefault("cov", None)
        return cls(
            frame=frame, timestamp=timestamp, status=status, R_ch=_NAN33, t_ch=_NAN3, R=_NAN33,
            p=_NAN3, v=_NAN3, w=_NAN3, labels=labels, n_visible=n_visible, **kw,
        )  # fmt: skip


def within_coast_limit(sigmas: tuple[float, float], measured: tuple[float, float],
                       limit: tuple[float, float]) -> bool:
    """Whether a frame without enough markers, its (rot_sigma_deg, pos_sigma_mm) ``sigmas``,
    adds no more than ``limit`` (deg, mm; in quadrature) to the last measured frame's
    ``measured`` and so reports its pose (TrackerConfig.coast_limit)."""
    return all(s * s - m * m <= b * b for s, m, b in zip(sigmas, measured, limit, strict=True))
