"""comparison.html of ``wristtrack compare``: one self-contained page (figures embedded as PNG
data URIs, like report.html) with the alignment found, the overlaid angle traces, the
Bland-Altman plots and the agreement tables."""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from wristtrack import __version__
from wristtrack.analysis.compare.comparison import Comparison, comparison_json
from wristtrack.io.atomic import write_bytes_atomic, write_text_atomic
from wristtrack.report.figures import AXIS_COLOURS, AXIS_NAMES, WIDTH_IN, figure_png

_CSS = """
body { font-family: "DejaVu Sans", Arial, Helvetica, sans-serif; font-size: 10pt;
       color: #111; max-width: 190mm; margin: 1em auto; padding: 0 0.5em; }
h1 { font-size: 16pt; } h2 { font-size: 12pt; border-bottom: 1px solid #888; }
table { border-collapse: collapse; margin: 0.3em 0 0.8em; }
th, td { border: 1px solid #bbb; padding: 2px 6px; text-align: right; }
th { background: #eee; } td.l, th.l { text-align: left; }
figure { margin: 0.6em 0; break-inside: avoid; } figure img { width: 100%; height: auto; }
figcaption { font-size: 9pt; color: #333; }
.note { border-left: 4px solid #e41a1c; background: #fff3f3; padding: 4px 8px; }
"""


def _new(height_in: float, ncols: int = 1, nrows: int = 1):
    fig = Figure(figsize=(WIDTH_IN, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols, squeeze=False)


def alignment_figure(series: dict[str, np.ndarray], offset_s: float) -> Figure:
    """Speed of both systems on our clock, after the alignment found."""
    fig, ax = _new(2.4)
    a = ax[0, 0]
    a.plot(series["speed_t"], series["speed_ours"], color="#1f77b4", lw=1.2, label="ours")
    a.plot(series["ref_speed_t"], series["ref_speed"], color="#111", lw=0.8, ls="--",
           label=f"reference, shifted by {-offset_s * 1e3:+.1f} ms")
    lo, hi = np.nanmin(series["speed_t"]), np.nanmax(series["speed_t"])
    a.set_xlim(lo, hi)
    a.set_xlabel("our time (s)")
    a.set_ylabel("wrist speed (m/s)")
    a.legend(loc="upper right", fontsize=8)
    return fig


def angles_figure(series: dict[str, np.ndarray]) -> Figure:
    """Our wrist angles over the reference's, per axis."""
    fig, ax = _new(5.4, 1, 3)
    for j, name in enumerate(AXIS_NAMES):
        a = ax[j, 0]
        a.plot(series["t"], series["ref_deg"][:, j], color="#111", lw=1.6, alpha=0.6,
               label="reference")
        a.plot(series["t"], series["ours_deg"][:, j], color=AXIS_COLOURS[j], lw=1.0,
               label="ours")
        a.set_ylabel(f"{name} (deg)")
        a.legend(loc="upper right", fontsize=7)
    ax[-1, 0].set_xlabel("our time (s)")
    return fig


def bland_altman_figure(series: dict[str, np.ndarray], result: dict[str, Any]) -> Figure:
    """Difference against mean per frame, with the bias and the 95 % limits of agreement."""
    fig, ax = _new(2.6, 3, 1)
    for j, name in enumerate(AXIS_NAMES):
        a = ax[0, j]
        x, y = series["ours_deg"][:, j], series["ref_deg"][:, j]
        ok = np.isfinite(x) & np.isfinite(y)
        a.scatter((x[ok] + y[ok]) / 2, x[ok] - y[ok], s=4, color=AXIS_COLOURS[j], alpha=0.6)
        ba = result["bland_altman"][name]
        for key, style in (("bias_deg", "-"), ("loa_low_deg", "--"), ("loa_high_deg", "--")):
            if ba[key] is not None:
                a.axhline(ba[key], color="#333", ls=style, lw=0.9)
        a.set_title(name, fontsize=9)
        a.set_xlabel("mean of both (deg)")
    ax[0, 0].set_ylabel("ours - reference (deg)")
    return fig


def error_figure(series: dict[str, np.ndarray]) -> Figure:
    """Position and orientation disagreement per frame after the registration."""
    fig, ax = _new(2.6, 1, 2)
    ax[0, 0].plot(series["t"], np.linalg.norm(series["pos_err_mm"], axis=1), lw=0.9)
    ax[0, 0].set_ylabel("position (mm)")
    ax[1, 0].plot(series["t"], series["rot_err_deg"], lw=0.9, color="#d62728")
    ax[1, 0].set_ylabel("orientation (deg)")
    ax[1, 0].set_xlabel("our time (s)")
    return fig


def _f(x: Any, digits: int = 2) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def _img(fig: Figure, caption: str) -> str:
    data = base64.b64encode(figure_png(fig)).decode("ascii")
    return (f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def render_comparison_html(comparison: Comparison) -> str:
    r, s = comparison.result, comparison.series
    e = html.escape
    sig = r["registration"]["sigma"]
    rows = "".join(
        f"<tr><td class=l>{a}</td><td>{_f(r['bland_altman'][a]['bias_deg'])}</td>"
        f"<td>{_f(r['bland_altman'][a]['loa_low_deg'])} .. "
        f"{_f(r['bland_altman'][a]['loa_high_deg'])}</td><td>{_f(r['icc'][a], 3)}</td>"
        f"<td>{_f(r['range_of_motion_deg'][a]['ours'], 1)}</td>"
        f"<td>{_f(r['range_of_motion_deg'][a]['reference'], 1)}</td>"
        f"<td>{_f(r['rom_error_deg'][a])}</td></tr>"
        for a in AXIS_NAMES
    )
    reach_rows = ""
    for key, label, unit in (("peak_speed_m_s", "peak speed", "m/s"),
                             ("movement_time_s", "movement time", "s")):
        ba = r["reaches"][key]["bland_altman"]
        reach_rows += (
            f"<tr><td class=l>{label} ({unit})</td><td>{r['reaches']['paired']}</td>"
            f"<td>{_f(ba['bias'], 3)}</td><td>{_f(ba['loa_low'], 3)} .. "
            f"{_f(ba['loa_high'], 3)}</td><td>{_f(r['reaches'][key]['icc'], 3)}</td></tr>"
        )
    if r.get("time_offset_given"):
        coarse_label, coarse_note = "time offset given (--time-offset), not fitted", "-"
    else:
        coarse_label = "coarse offset (speed cross-correlation)"
        coarse_note = f"peak {_f(r['speed_correlation'])}"
    notes = "".join(f"<p class=note>{e(n)}</p>"
                    for n in [*r.get("warnings", []), *r["reference"]["notes"]])
    ref = r["reference"]
    body = f"""
<h1>Validation against a reference system</h1>
<p>Run <code>{e(r['run'])}</code> against <code>{e(ref['path'])}</code> ({e(ref['kind'])},
{ref['rate_hz']:.4g} Hz, stored in {e(ref['units'])}, {ref['frames']} frames,
{ref['frames_with_pose']} with a pose; rigid-fit residual {_f(ref['rigid_fit_rms_mm'], 3)} mm).
wristtrack {e(__version__)}.</p>{notes}
<h2>Alignment found</h2>
<table><tr><th class=l>quantity</th><th>value</th><th>1 sigma</th></tr>
<tr><td class=l>time offset (reference = ours + offset)</td><td>{r['time_offset_s'] * 1e3:.2f} ms
</td><td>{sig['offset_s'] * 1e3:.2f} ms</td></tr>
<tr><td class=l>clock ratio</td><td>{r['clock_ratio']:.6f}</td><td>{sig['ratio']:.1e}</td></tr>
<tr><td class=l>registration rotation / translation</td><td>see comparison.json</td>
<td>{sig['rotation_deg']:.3f} deg / {sig['translation_mm']:.2f} mm</td></tr>
<tr><td class=l>{coarse_label}</td><td>{r['coarse_offset_s'] * 1e3:.1f}
ms</td><td>{coarse_note}</td></tr></table>
{_img(alignment_figure(s, r['time_offset_s']), 'Wrist speed of both systems after alignment')}
<h2>Agreement</h2>
<p>{r['frames_compared']} frames compared ({r['frames_registered']} used by the registration).
Position RMSE {_f(r['pos_rmse_mm'])} mm, orientation RMSE {_f(r['rot_rmse_deg'])} deg.</p>
{_noise_paragraph(r)}
<table><tr><th class=l>angle</th><th>bias (deg)</th><th>95 % LoA (deg)</th><th>ICC(2,1)</th>
<th>RoM ours</th><th>RoM ref.</th><th>RoM error</th></tr>{rows}</table>
{_img(angles_figure(s), 'Wrist angles: ours (colour) over the reference (grey)')}
{_img(bland_altman_figure(s, r), 'Bland-Altman plots: bias (solid) and 95 % limits (dashed)')}
{_img(error_figure(s), 'Disagreement per frame after registration')}
<h2>Reaches</h2>
<p>{r['reaches']['ours']} reaches in our run, {r['reaches']['reference']} in the reference,
{r['reaches']['paired']} paired by time.</p>
<table><tr><th class=l>measure</th><th>pairs</th><th>bias</th><th>95 % LoA</th>
<th>ICC(2,1)</th></tr>{reach_rows}</table>
"""
    return (f"<!DOCTYPE html><html lang=en><head><meta charset=utf-8>"
            f"<title>wristtrack comparison</title><style>{_CSS}</style></head>"
            f"<body>{body}</body></html>\n")


def _noise_paragraph(r: dict) -> str:
    """What of the RMSEs is the reference's own noise (empty without an estimate)."""
    noise = r.get("reference_noise")
    if not noise:
        return ""
    return (f"<p>The reference's own noise, read off its rigid fits: {_f(noise['marker_mm'], 3)}"
            f" mm per marker coordinate, {_f(noise['position_mm'], 3)} mm and "
            f"{_f(noise['rotation_deg'], 3)} deg where compared. Net of it (in quadrature): "
            f"position {_f(r['pos_rmse_net_mm'])} mm, orientation {_f(r['rot_rmse_net_deg'])} "
            "deg, our own error if the reference's markers moved only by its noise (skin "
            "motion between them counts as noise, so on a real hand these are lower bounds)."
            "</p>")


def write_comparison_html(path: str | Path, comparison: Comparison) -> Path:
    path = Path(path)
    write_bytes_atomic(path, render_comparison_html(comparison).encode("utf-8"))
    return path


def write_comparison(out_dir: str | Path, comparison: Comparison) -> tuple[Path, Path]:
    """comparison.json and comparison.html in ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    json_path = out / "comparison.json"
    write_text_atomic(json_path, comparison_json(comparison))
    return json_path, write_comparison_html(out / "comparison.html", comparison)
