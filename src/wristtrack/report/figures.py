"""The report's figures: one pure function per figure, arrays in, a Matplotlib Figure out.

Figures are built on ``matplotlib.figure.Figure`` with the Agg canvas, never through pyplot, so
nothing global changes and no display is needed. NaN rows (frames without an estimate) break
the lines: a gap in tracking shows as a gap, never as a straight line bridging it. Every
function accepts a run with no estimate at all and then draws the empty state with a note.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

AXIS_NAMES = ("deviation", "flexion", "pronation")
AXIS_COLOURS = ("#1f77b4", "#d62728", "#2ca02c")
HAND_AXIS_COLOURS = ("#e41a1c", "#2ca02c", "#1f4fe0")  # X red, Y green, Z blue, as on video
STATUS_COLOURS = {
    "tracking": "#4daf4a",
    "coasting": "#ffb000",
    "initialising": "#9e9e9e",
    "lost": "#e41a1c",
    "skipped": "#6a3d9a",
}
NO_ESTIMATE = "no estimate in this run"
WIDTH_IN = 7.2  # fits the printable width of A4 with 15 mm margins
MAX_PLOT_POINTS = 4000  # longer series are thinned for drawing (gaps kept)

# The three planar views of the paper (Figs. 3 and 5): (horizontal, vertical) axis indices.
PLANES = (("XY", 0, 1), ("ZX", 2, 0), ("ZY", 2, 1))


def _new(height_in: float) -> Figure:
    fig = Figure(figsize=(WIDTH_IN, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _plane_axes(ax, title: str, plane: str) -> None:
    """Title, millimetre labels and grid of one of the PLANES' panels ("XY", "ZX", "ZY")."""
    ax.set_title(title)
    ax.set_xlabel(f"{plane[0]} (mm)")
    ax.set_ylabel(f"{plane[1]} (mm)")
    ax.grid(True, lw=0.4, alpha=0.5)


def _empty_note(ax, text: str = NO_ESTIMATE) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center",
            fontsize=10, color="#666666", style="italic")


def plot_indices(finite: np.ndarray, max_points: int = MAX_PLOT_POINTS) -> np.ndarray:
    """Row indices to draw: every k-th row of a long series, plus both sides of every gap edge.

    Keeping the rows where the estimate appears or disappears means thinning never closes a gap.
    """
    finite = np.asarray(finite, dtype=bool)
    n = finite.size
    if n <= max_points:
        return np.arange(n)
    step = int(np.ceil(n / max_points))
    edges = np.flatnonzero(finite[1:] != finite[:-1])
    keep = np.concatenate([np.arange(0, n, step), edges, edges + 1, [n - 1]])
    return np.unique(keep)


def figure_png(fig: Figure, dpi: int = 130) -> bytes:
    """The figure as PNG bytes.

    One Agg draw and OpenCV's PNG encoder: savefig would lay the figure out and draw it twice,
    which made up most of the report's time.
    """
    fig.set_dpi(dpi)
    canvas = fig.canvas
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    ok, png = cv2.imencode(".png", cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR))
    if not ok:  # pragma: no cover - encoding an in-memory uint8 image does not fail
        raise RuntimeError("PNG encoding failed")
    return png.tobytes()


def _time_axis(ax, t: np.ndarray) -> None:
    ax.set_xlabel("time (s)")
    if t.size and np.isfinite(t).any():
        lo, hi = np.nanmin(t), np.nanmax(t)
        ax.set_xlim(lo, hi if hi > lo else lo + 1.0)


def trajectory_figure(p_mm: np.ndarray) -> Figure:
    """Wrist trajectory in W0 (mm) in the XY, ZX and ZY planes (the paper's Fig. 5).

    ``p_mm`` (N,3), NaN rows where there is no estimate. Start is a circle, end a square.
    """
    p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
    finite = np.isfinite(p).all(axis=1)
    fig = _new(2.9)
    axes = fig.subplots(1, 3)
    idx = plot_indices(finite)
    for ax, (name, i, j) in zip(axes, PLANES, strict=True):
        _plane_axes(ax, f"{name} plane", name)
        if not finite.any():
            _empty_note(ax)
            continue
        ax.plot(p[idx, i], p[idx, j], color="black", lw=1.0)
        first, last = np.flatnonzero(finite)[[0, -1]]
        ax.plot(p[first, i], p[first, j], "o", color="#2ca02c", ms=5, label="start")
        ax.plot(p[last, i], p[last, j], "s", color="#d62728", ms=5, label="end")
        ax.set_aspect("equal", adjustable="datalim")
    if finite.any():
        axes[0].legend(loc="best", fontsize=7)
    fig.suptitle("Wrist trajectory relative to the neutral frame W0", fontsize=10)
    return fig


def angles_figure(t: np.ndarray, angles_deg: np.ndarray) -> Figure:
    """Deviation, flexion and pronation (deg) against time, each with its range of motion.

    The band between the minimum and maximum is shaded and both extremes are marked where they
    occur. ``angles_deg`` (N,3) in the order of AXIS_NAMES, NaN rows where there is no estimate.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    a = np.asarray(angles_deg, dtype=float).reshape(-1, 3)
    fig = _new(5.4)
    axes = fig.subplots(3, 1, sharex=True)
    for k, (ax, name, colour) in enumerate(zip(axes, AXIS_NAMES, AXIS_COLOURS, strict=True)):
        y = a[:, k]
        finite = np.isfinite(y)
        ax.set_ylabel(f"{name} (deg)")
        ax.grid(True, lw=0.4, alpha=0.5)
        if not finite.any():
            _empty_note(ax)
            continue
        idx = plot_indices(finite)
        ax.plot(t[idx], y[idx], color=colour, lw=1.2)
        i_min, i_max = int(np.nanargmin(y)), int(np.nanargmax(y))
        lo, hi = y[i_min], y[i_max]
        ax.axhspan(lo, hi, color=colour, alpha=0.08, lw=0)
        for level in (lo, hi):
            ax.axhline(level, color=colour, lw=0.7, ls="--")
        ax.plot(t[i_min], lo, "v", color=colour, ms=6)
        ax.plot(t[i_max], hi, "^", color=colour, ms=6)
        ax.set_title(f"{name}: RoM {lo:.1f} to {hi:.1f} deg (range {hi - lo:.1f} deg)",
                     fontsize=9, loc="left")
    _time_axis(axes[-1], t)
    return fig


def speed_figure(
    t: np.ndarray,
    speed_m_s: np.ndarray,
    reaches: Sequence[tuple[int, int]] = (),
    peaks: Sequence[int] = (),
    raw_speed_m_s: np.ndarray | None = None,
) -> Figure:
    """Wrist speed against time (the paper's Fig. 6), reaches shaded and numbered.

    ``speed_m_s`` is the speed the reaches were measured on; ``reaches`` are inclusive
    (start, end) frame indices (onset, offset); ``peaks`` the frame of each reach's peak speed,
    marked with a triangle. ``raw_speed_m_s``, if given, is drawn faintly behind (the speed
    before the analysis' low-pass).
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    s = np.asarray(speed_m_s, dtype=float).reshape(-1)
    finite = np.isfinite(s)
    raw = None if raw_speed_m_s is None else np.asarray(raw_speed_m_s, dtype=float).reshape(-1)
    fig = _new(2.8)
    ax = fig.subplots()
    ax.set_ylabel("speed (m/s)")
    ax.grid(True, lw=0.4, alpha=0.5)
    _time_axis(ax, t)
    if not finite.any():
        _empty_note(ax)
        return fig
    idx = plot_indices(finite)
    top = float(np.nanmax(s))
    if raw is not None and np.isfinite(raw).any():
        ax.plot(t[idx], raw[idx], color="#999999", lw=0.8, label="as tracked")
        top = max(top, float(np.nanmax(raw)))
    ax.plot(t[idx], s[idx], color="black", lw=1.2, label="wrist speed (analysed)")
    for n, (start, end) in enumerate(reaches, 1):
        ax.axvspan(t[start], t[end], color="#1f77b4", alpha=0.15, lw=0,
                   label="reach (onset to offset)" if n == 1 else None)
        ax.text((t[start] + t[end]) / 2, top * 1.04, str(n), ha="center", va="bottom", fontsize=8)
    if len(peaks):
        pk = np.asarray(peaks, dtype=int)
        ax.plot(t[pk], s[pk], "v", color="#d62728", ms=6, label="peak speed")
    ax.set_ylim(0, top * 1.15 if top > 0 else 1.0)
    ax.legend(loc="upper right", fontsize=7)
    return fig


def sample_instants(
    finite: np.ndarray, count: int = 12, p: np.ndarray | None = None, R: np.ndarray | None = None
) -> np.ndarray:
    """Up to ``count`` frame indices among those with an estimate, spread over the movement.

    Walking forward, a frame is taken once its pose differs enough from the last one taken
    (20 mm or 10 degrees count as one unit; the step is the largest departure from the first
    pose over count - 1, at least a quarter unit), so rests do not take the samples and tracking
    jitter does not add up as a path would. Evenly in time when nothing moves.
    """
    rows = np.flatnonzero(np.asarray(finite, dtype=bool))
    if rows.size <= count:
        return rows
    rows = rows[np.unique(np.linspace(0, rows.size - 1, min(rows.size, 4000)).astype(int))]
    n = rows.size
    pos = np.zeros((n, 3)) if p is None else np.asarray(p, float)[rows] / 20.0
    rot = np.repeat(np.eye(3)[None], n, 0) if R is None else np.asarray(R, float)[rows]
    deg10 = np.radians(10.0)

    def departure(i: int) -> np.ndarray:  # pose difference of every row from row i, in units
        cos = (np.einsum("ij,nij->n", rot[i], rot) - 1.0) / 2.0
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        return np.linalg.norm(pos - pos[i], axis=1) + angle / deg10

    step = max(float(departure(0).max()) / (count - 1), 0.25)
    picks, last = [0], 0
    pos_l, rot_l = pos.tolist(), rot  # scalar loop: one small comparison per row
    for i in range(1, n):
        dp = math.dist(pos_l[i], pos_l[last])
        if dp >= step:
            picks.append(i)
            last = i
            continue
        cos = (float(np.vdot(rot_l[i], rot_l[last])) - 1.0) / 2.0
        if dp + math.acos(min(1.0, max(-1.0, cos))) / deg10 >= step:
            picks.append(i)
            last = i
    if len(picks) == 1:
        return rows[np.round(np.linspace(0, n - 1, count)).astype(int)]
    # The final pose is always shown: it replaces the last pick when the two are close.
    if picks[-1] != n - 1:
        if departure(n - 1)[picks[-1]] >= step / 2:
            picks.append(n - 1)
        else:
            picks[-1] = n - 1
    picks_a = np.asarray(picks)
    if picks_a.size > count:
        picks_a = picks_a[np.round(np.linspace(0, picks_a.size - 1, count)).astype(int)]
    return rows[picks_a]


def orientation_figure(p_mm: np.ndarray, R: np.ndarray, count: int = 12) -> Figure:
    """The wrist frame drawn at sampled instants along the trajectory, in the XY, ZX and ZY
    planes of W0 (the paper's Fig. 3): hand X red, Y green, Z blue.

    ``p_mm`` (N,3) positions in W0, ``R`` (N,3,3) hand orientations relative to W0 (columns are
    the hand axes in W0); NaN rows where there is no estimate.
    """
    p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    finite = np.isfinite(p).all(axis=1) & np.isfinite(R).all(axis=(1, 2))
    fig = _new(3.0)
    axes = fig.subplots(1, 3)
    picks = sample_instants(finite, count, p, R)
    if picks.size:
        extent = float(np.ptp(p[finite], axis=0).max())
        length = max(0.15 * extent, 15.0)  # mm; a still hand still shows readable axes
    idx = plot_indices(finite)
    for ax, (name, i, j) in zip(axes, PLANES, strict=True):
        _plane_axes(ax, f"view in the {name} plane", name)
        if not picks.size:
            _empty_note(ax)
            continue
        ax.plot(p[idx, i], p[idx, j], color="#bbbbbb", lw=0.8)
        for f in picks:
            for k, colour in enumerate(HAND_AXIS_COLOURS):
                tip = p[f] + length * R[f, :, k]
                ax.plot([p[f, i], tip[i]], [p[f, j], tip[j]], color=colour, lw=1.3)
            ax.plot(p[f, i], p[f, j], "o", color="black", ms=2.5)
        ax.set_aspect("equal", adjustable="datalim")
    handles = [Patch(color=c, label=f"hand {a}") for c, a in zip(HAND_AXIS_COLOURS, "XYZ",
                                                                    strict=True)]
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=7)
    fig.suptitle(f"Wrist frame orientation at {picks.size} instants along the trajectory (W0)",
                 fontsize=10)
    return fig


def status_runs(status: np.ndarray) -> list[tuple[str, int, int]]:
    """(status, first row, last row) of each run of equal consecutive statuses."""
    status = np.asarray(status).astype(str)
    if status.size == 0:
        return []
    cuts = np.flatnonzero(status[1:] != status[:-1]) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts - 1, [status.size - 1]])
    return [(str(status[a]), int(a), int(b)) for a, b in zip(starts, ends, strict=True)]


def quality_figure(
    t: np.ndarray,
    status: np.ndarray,
    n_visible: np.ndarray,
    n_clutter: np.ndarray,
    nis: np.ndarray | None = None,
    nis_dof: np.ndarray | None = None,
    pos_sigma_mm: np.ndarray | None = None,
    rot_sigma_deg: np.ndarray | None = None,
) -> Figure:
    """Tracking quality over time: status as coloured bands, markers seen and clutter blobs,
    normalised innovation (NIS per degree of freedom, 1 expected) and the filter's 1-sigma
    uncertainty when those columns exist.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    status = np.asarray(status).astype(str).reshape(-1)
    panels = ["status", "counts"]
    nis_norm = None
    if nis is not None and nis_dof is not None:
        dof = np.asarray(nis_dof, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            nis_norm = np.where(dof > 0, np.asarray(nis, dtype=float) / dof, np.nan)
        if np.isfinite(nis_norm).any():
            panels.append("nis")
    sig = [np.asarray(x, dtype=float) if x is not None else None
           for x in (pos_sigma_mm, rot_sigma_deg)]
    if any(x is not None and np.isfinite(x).any() for x in sig):
        panels.append("sigma")
    ratios = [0.35] + [1.0] * (len(panels) - 1)
    fig = _new(1.0 + 1.35 * len(panels))
    axes = fig.subplots(len(panels), 1, sharex=True, gridspec_kw={"height_ratios": ratios})
    # Band edges halfway between frames so each frame owns its own slot.
    if t.size > 1:
        mid = (t[1:] + t[:-1]) / 2
        lo = np.concatenate([[t[0] - (mid[0] - t[0])], mid])
        hi = np.concatenate([mid, [t[-1] + (t[-1] - mid[-1])]])
    else:
        lo, hi = t - 0.5, t + 0.5
    seen = []
    for name, a, b in status_runs(status):
        colour = STATUS_COLOURS.get(name, "#000000")
        for ax in axes:
            ax.axvspan(lo[a], hi[b], color=colour, alpha=0.9 if ax is axes[0] else 0.10, lw=0)
        if name not in seen:
            seen.append(name)
    axes[0].set_yticks([])
    axes[0].set_ylabel("status", rotation=0, ha="right", va="center")
    axes[0].legend(handles=[Patch(color=STATUS_COLOURS.get(s, "#000000"), label=s) for s in seen],
                   loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=max(len(seen), 1),
                   fontsize=7, frameon=False)
    ax = axes[1]
    ax.step(t, np.asarray(n_visible, dtype=float), where="mid", color="#1f4fe0",
            label="markers measured")
    ax.step(t, np.asarray(n_clutter, dtype=float), where="mid", color="#e41a1c",
            label="clutter blobs")
    ax.set_ylabel("count")
    ax.set_ylim(-0.3, max(6.5, float(np.nanmax(n_clutter, initial=0)) + 0.5))
    ax.legend(loc="upper right", fontsize=7)
    ax.grid(True, lw=0.4, alpha=0.5)
    k = 2
    if "nis" in panels:
        ax = axes[k]
        k += 1
        finite = np.isfinite(nis_norm)
        idx = plot_indices(finite)
        ax.plot(t[idx], nis_norm[idx], ".", color="black", ms=2.5)
        ax.axhline(1.0, color="#666666", ls="--", lw=0.8)
        ax.set_yscale("log")
        ax.set_ylabel("NIS / dof")
        ax.grid(True, lw=0.4, alpha=0.5)
    if "sigma" in panels:
        ax = axes[k]
        for values, label, colour in ((sig[0], "position 1σ (mm)", "#1f77b4"),
                                      (sig[1], "orientation 1σ (deg)", "#9467bd")):
            if values is not None and np.isfinite(values).any():
                idx = plot_indices(np.isfinite(values))
                ax.plot(t[idx], values[idx], color=colour, lw=1.0, label=label)
        ax.set_ylabel("uncertainty")
        ax.legend(loc="upper right", fontsize=7)
        ax.grid(True, lw=0.4, alpha=0.5)
    _time_axis(axes[-1], t)
    return fig
