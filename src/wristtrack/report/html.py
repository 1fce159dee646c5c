"""The clinician's report of a run: one self-contained, printable report.html plus figures/*.png.

Everything comes from the run folder (poses.csv and summary.json), so ``wristtrack report
RUN_DIR`` can regenerate it at any time. Figures are embedded as base64 PNG data URIs: the file
opens offline, can be mailed as is, and prints on A4. Reach metrics come from
:mod:`wristtrack.analysis.kinematics` (summary.json's ``kinematics`` when the run stored it).
"""

from __future__ import annotations

import base64
import datetime as dt
import html
import math
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack import __version__
from wristtrack.analysis.kinematics import analyse, speed_series
from wristtrack.analysis.kinematics_settings import KinematicsSettings
from wristtrack.geometry import matrix_from_quat
from wristtrack.io.atomic import write_bytes_atomic
from wristtrack.io.run_folder import SURVEYED_HAND, read_run
from wristtrack.report import figures as rf

FIGURES = (
    ("trajectory", "Wrist trajectory (XY, ZX and ZY planes)"),
    ("angles", "Wrist angles against time with the range of motion"),
    ("speed", "Wrist speed profile with the reaches"),
    ("orientation", "Wrist frame orientation along the trajectory"),
    ("quality", "Tracking quality over time"),
)

_CSS = """
body { font-family: "DejaVu Sans", Arial, Helvetica, sans-serif; font-size: 10pt;
       color: #111; max-width: 190mm; margin: 1em auto; padding: 0 0.5em; }
h1 { font-size: 16pt; margin: 0 0 0.3em; }
h2 { font-size: 12pt; border-bottom: 1px solid #888; margin: 1.2em 0 0.4em; }
table { border-collapse: collapse; margin: 0.3em 0 0.8em; }
th, td { border: 1px solid #bbb; padding: 2px 6px; text-align: right; }
th { background: #eee; } td.l, th.l { text-align: left; }
dl.meta { display: grid; grid-template-columns: max-content auto; gap: 1px 10px; margin: 0; }
dl.meta dt { font-weight: bold; } dl.meta dd { margin: 0; }
.note { border-left: 4px solid #e41a1c; background: #fff3f3; padding: 4px 8px; margin: 0.5em 0; }
figure { margin: 0.6em 0; break-inside: avoid; page-break-inside: avoid; }
figure img { width: 100%; height: auto; }
figcaption { font-size: 9pt; color: #333; }
@page { size: A4; margin: 15mm; }
@media print {
  body { max-width: none; margin: 0; padding: 0; font-size: 9.5pt; }
  h2 { break-after: avoid; page-break-after: avoid; }
  table, .note { break-inside: avoid; page-break-inside: avoid; }
}
"""

# Not needed to read or print the report: lets a headless browser confirm that every embedded
# figure decodes (the test suite checks this through Chromium).
_IMAGE_CHECK = """<script>
window.addEventListener("load", function () {
  var ok = 0, bad = 0;
  for (var i = 0; i < document.images.length; i++) {
    var im = document.images[i];
    if (im.complete && im.naturalWidth > 0) { ok++; } else { bad++; }
  }
  document.body.setAttribute("data-images-loaded", ok);
  document.body.setAttribute("data-images-failed", bad);
});
</script>"""


# ----------------------------------------------------------------------------- run loading


def _kinematics(columns: dict[str, np.ndarray], summary: dict[str, Any]) -> dict[str, Any]:
    """Reach and range-of-motion analysis: the run's stored one (summary.json), else computed
    now (runs written before summary.json carried it)."""
    if isinstance(summary.get("kinematics"), dict):
        return summary["kinematics"]
    return analyse(columns)


def _speeds(
    columns: dict[str, np.ndarray], kin: dict[str, Any] | None
) -> tuple[np.ndarray, np.ndarray]:
    """(as tracked, as analysed) wrist speed (kinematics.speed_series), with the low-pass the
    run's stored analysis used."""
    settings = (kin or {}).get("settings") or {}
    cutoff = settings.get("lowpass_hz", KinematicsSettings().lowpass_hz)
    if not (isinstance(cutoff, int | float) and cutoff > 0):
        cutoff = 0.0  # no low-pass: the analysed speed is the tracked one
    return speed_series(columns, KinematicsSettings(lowpass_hz=float(cutoff)))


# ------------------------------------------------------------------------------ figures


def _reach_frames(kin: dict[str, Any] | None, n: int) -> list[tuple[int, int]]:
    if not kin:
        return []
    out = []
    for r in kin.get("reaches", []):
        a, b = r.get("start_frame"), r.get("end_frame")
        if isinstance(a, int) and isinstance(b, int) and 0 <= a <= b < n:
            out.append((a, b))
    return out


def build_figures(columns: dict[str, np.ndarray], kin: dict[str, Any] | None) -> dict[str, Any]:
    """The report's Matplotlib figures by name (see FIGURES), from poses.csv columns."""
    t = columns["timestamp"]
    p_m = np.column_stack([columns[c] for c in ("tx", "ty", "tz")])
    q = np.column_stack([columns[c] for c in ("qw", "qx", "qy", "qz")])
    R = np.full((len(t), 3, 3), np.nan)
    ok = np.isfinite(q).all(axis=1)
    if ok.any():
        R[ok] = matrix_from_quat(q[ok])
    angles = np.column_stack([columns[f"{a}_deg"] for a in rf.AXIS_NAMES])
    raw_speed, speed = _speeds(columns, kin)
    reaches = _reach_frames(kin, len(t))
    peaks = [a + int(np.nanargmax(speed[a:b + 1])) for a, b in reaches
             if np.isfinite(speed[a:b + 1]).any()]
    return {
        "trajectory": rf.trajectory_figure(p_m * 1000.0),
        "angles": rf.angles_figure(t, angles),
        "speed": rf.speed_figure(t, speed, reaches, peaks, raw_speed),
        "orientation": rf.orientation_figure(p_m * 1000.0, R),
        "quality": rf.quality_figure(
            t, columns["status"], columns["n_visible"], columns["n_clutter"],
            columns.get("nis"), columns.get("nis_dof"),
            columns.get("pos_sigma_mm"), columns.get("rot_sigma_deg"),
        ),
    }


# --------------------------------------------------------------------------------- HTML


def _fmt(value: Any, digits: int, scale: float = 1.0) -> str:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return "&ndash;"
    return f"{value * scale:.{digits}f}"


def _e(text: Any) -> str:
    return html.escape(str(text))


def _meta(summary: dict[str, Any], run: Path) -> str:
    software = summary.get("software") or {}
    written = dt.datetime.fromtimestamp((run / "summary.json").stat().st_mtime, dt.UTC)
    rows = [
        ("Recording", summary.get("source", "unknown")),
        ("Run folder", run.resolve()),
        ("Run written", written.strftime("%Y-%m-%d %H:%M UTC")),
        ("Report generated", dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")),
        ("Software", f"{software.get('name', 'wristtrack')} {software.get('version', '?')} "
                     f"(report by wristtrack {__version__})"),
    ]
    settings = summary.get("settings") or {}
    if settings:
        rows.append(("Tracker", f"model {settings.get('model', '?')}, association "
                                f"{settings.get('association', '?')}, depth in updates "
                                f"{'yes' if settings.get('use_depth') else 'no'}, detector "
                                f"{settings.get('detector', 'default')}"
                                f"{', RTS-smoothed' if settings.get('smoothed') else ''}"))
    smoothing = summary.get("smoothing_process_noise")
    if smoothing:  # --smooth's process noise, learned from the recording (pipeline/refit.py)
        rows.append(("Smoothing", _smoothing_noise(smoothing)))
    origin = settings.get("hand_layout_from")
    if origin:  # hand.json, the still start or surveyed (tracking/layout_survey.py)
        surveyed = summary.get("hand_layout_surveyed")
        rows.append(("Hand layout", origin + ("; surveyed over the session for the next one: "
                                              f"{SURVEYED_HAND}" if surveyed else "")))
    noise = summary.get("measurement_noise")
    if noise:  # what the tracker learned of this camera's blobs and this hand's skin
        rows.append(("Noise learned", _learned_noise(noise)))
    timing = _depth_timing(summary, settings)
    if timing:
        rows.append(("Depth timing", timing))
    rows.append(("Colour shutter", _shutter(summary.get("camera") or {},
                                            settings.get("timing_modelled", True))))
    offset = summary.get("depth_registration")
    if offset:  # --follow-offset: the depth map's offset from the colour image, as estimated
        rows.append(("Depth registration", _registration(offset)))
    conventions = summary.get("conventions") or {}
    labels = {"angles": "Angle sequence and signs", "side": "Side", "neutral": "Neutral posture",
              "hand_frame": "Hand frame", "units": "Units", "velocities": "Velocities"}
    rows += [(labels.get(k, k), v) for k, v in conventions.items()]
    items = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in rows)
    return f'<dl class="meta">{items}</dl>'


def _smoothing_noise(noise: dict[str, Any]) -> str:
    """summary.json's smoothing_process_noise in words."""
    model, learned = noise.get("model_angular_accel"), noise.get("learned_angular_accel")
    unit = "(rad/s\u00b2)\u00b2 s"
    if learned is None:
        return (f"at the model's angular process noise, {_fmt(model, 2)} {unit} (the recording's "
                "rates said too little to learn it, or about as much)")
    if not noise.get("refit_kept"):
        return (f"at the model's angular process noise, {_fmt(model, 2)} {unit}: tracked again at "
                f"the {_fmt(learned, 3)} its rates showed, the hand was lost in more frames")
    return (f"tracked again and smoothed at the angular process noise the recording's rates "
            f"showed, {_fmt(learned, 3)} {unit} (model {_fmt(model, 2)}, kept for the filtered "
            "poses)")


def _learned_noise(noise: dict[str, Any]) -> str:
    """summary.json's measurement_noise in words (tracking/noise_scale.py)."""
    inflation, spread = noise.get("blob_error_inflation"), noise.get("blob_error_px")
    scatter = (f", their scatter about the hand's pose {_fmt(spread, 3)} px per frame"
               if spread is not None else "")
    correlated = (f", their errors correlated in time (half-second means {_fmt(inflation, 1)}x "
                  "the variance of white noise's)" if inflation is not None else "")
    return (f"blob centres taken at {_fmt(noise.get('pixel_sigma_px'), 2)} px (model "
            f"{_fmt(noise.get('pixel_sigma_model_px'), 2)} px){scatter}{correlated}; skin "
            f"slide over the knuckles at {_fmt(noise.get('skin_slide_sd_factor'), 2)}x the "
            "model's")


def _depth_timing(summary: dict[str, Any], settings: dict[str, Any]) -> str | None:
    """When each depth frame was captured against its colour frame (summary.json's
    depth_timing; camera.json's depth_delay_s in runs from before it), for a run that used
    depth."""
    if not settings.get("use_depth"):
        return None
    timing = summary.get("depth_timing")
    if timing is None:
        delay = (summary.get("camera") or {}).get("depth_delay_s")
        timing = {"from": "not stated"} if delay is None else \
            {"from": "camera.json", "delay_ms": 1e3 * delay}
    moved = "read where the hand had moved by then"
    if timing["from"] == "camera.json":
        return (f"each depth frame captured {_fmt(timing['delay_ms'], 1)} ms after its colour "
                f"frame (camera.json), {moved}")
    if timing["from"] == "frame stamps":
        return (f"each depth frame captured {_fmt(timing['delay_ms'], 1)} ms after its colour "
                f"frame on average ({_fmt(timing['min_ms'], 1)} to {_fmt(timing['max_ms'], 1)} "
                f"ms, from the camera's stamps of {timing['frames']} frames), each {moved}")
    return ("not stated: each depth frame taken as captured with its colour frame (give "
            "camera.json depth_delay_s where the streams are paired by time stamp; wristtrack "
            "timing measures it)")


def _shutter(camera: dict[str, Any], modelled: bool) -> str:
    """The colour camera's shutter (camera.json's readout_s), and whether the run's model
    could use it (summary.json's settings.timing_modelled)."""
    readout = camera.get("readout_s")
    if not readout:
        return ("global, or a rolling shutter not stated (give camera.json readout_s, the "
                "seconds from its top row to its bottom one; wristtrack timing measures it)")
    taken = ("each marker taken where it was when its row was read" if modelled else
             "each marker taken as read at the frame's time all the same (the model has no "
             "rates to move the hand by; --model default has)")
    return f"rolling, its rows read over {_fmt(1e3 * readout, 1)} ms, {taken}"


def _registration(offset: dict[str, Any]) -> str:
    """summary.json's depth_registration in words (tracking/offset_model.py)."""
    su, sv = offset["sd_px"]
    return (f"the depth map sits ({_fmt(offset['du_px'], 2)}, {_fmt(offset['dv_px'], 2)}) px "
            f"(sd {_fmt(su, 2)}, {_fmt(sv, 2)}) from the colour image: {offset['convention']}; "
            "recordings that agree on a pixel or more say the camera's depth-to-colour "
            "registration wants redoing")


def _notes(summary: dict[str, Any], columns: dict[str, np.ndarray]) -> str:
    notes = []
    frames = summary.get("frames") or {}
    has = np.isfinite(columns["tx"])
    if not has.any():
        notes.append(
            "No wrist estimate in this run: the tracker never initialised. It needs all six "
            "markers visible, with the hand still in the neutral posture, at the start."
        )
    elif not has.all():
        n_gaps = int(np.sum(has[1:] & ~has[:-1]) + (0 if has[0] else 1))
        notes.append(
            f"{int((~has).sum())} of {has.size} frames have no estimate ({n_gaps} gap"
            f"{'s' if n_gaps != 1 else ''}); curves break there and are not bridged."
        )
    notes += [str(w) for w in summary.get("warnings") or []]  # e.g. an unresolved planar flip
    if summary.get("interrupted"):
        notes.append("The run was interrupted: the report covers the frames processed.")
    if summary.get("skipped_frames"):
        notes.append(f"{len(summary['skipped_frames'])} frames were skipped as unusable input.")
    if frames.get("total") is not None and frames.get("total") != has.size:
        notes.append(f"summary.json counts {frames.get('total')} frames but poses.csv has "
                     f"{has.size} rows.")
    return "".join(f'<p class="note">{_e(n)}</p>' for n in notes)


def _cell(key: str, value: Any, digits: int, scale: float = 1.0) -> str:
    return f'<td id="{_e(key)}">{_fmt(value, digits, scale)}</td>'


def _summary_tables(summary: dict[str, Any], kin: dict[str, Any] | None) -> str:
    rom = summary.get("range_of_motion") or {}
    head = "".join(f"<th>{h}</th>" for h in ("min", "max", "range", "start", "end"))
    rows = []
    for axis in rf.AXIS_NAMES:
        r = rom.get(axis) or {}
        cells = "".join(_cell(f"rom-{axis}-{f}", r.get(f"{f}_deg"), 1)
                        for f in ("min", "max", "range", "start", "end"))
        rows.append(f'<tr><th class="l">{axis}</th>{cells}</tr>')
    out = [f'<table id="rom-table"><tr><th class="l">angle (deg)</th>{head}</tr>'
           f'{"".join(rows)}</table>']
    frames = summary.get("frames") or {}
    by_status = frames.get("by_status") or {}
    items = [
        ("peak-speed", "peak wrist speed (m/s)", summary.get("peak_speed_m_s"), 3, 1.0),
        ("mean-speed", "mean wrist speed (m/s)", summary.get("mean_speed_m_s"), 3, 1.0),
        ("path-length", "path length (mm)", summary.get("path_length_m"), 1, 1000.0),
        ("duration", "duration (s)", summary.get("duration_s"), 2, 1.0),
        ("frames-total", "frames", frames.get("total"), 0, 1.0),
        ("frames-tracked", "frames tracked (tracking or coasting)", frames.get("tracked"), 0, 1.0),
        ("frames-lost", "frames lost", frames.get("lost"), 0, 1.0),
        ("clutter", "clutter blobs seen (sum over frames)", summary.get("clutter_blobs_seen"),
         0, 1.0),
    ]
    if kin and isinstance(kin.get("angular_speed"), dict):
        items += [
            ("peak-angular-speed", "peak angular speed (deg/s)",
             kin["angular_speed"].get("peak_deg_s"), 1, 1.0),
            ("mean-angular-speed", "mean angular speed (deg/s)",
             kin["angular_speed"].get("mean_deg_s"), 1, 1.0),
        ]
    rows = [f'<tr><th class="l">{_e(label)}</th>{_cell(key, value, d, s)}</tr>'
            for key, label, value, d, s in items]
    status = ", ".join(f"{_e(k)} {_e(v)}" for k, v in by_status.items())
    rows.append(f'<tr><th class="l">frames by status</th><td class="l">{status}</td></tr>')
    out.append(f'<table id="movement-table">{"".join(rows)}</table>')
    return "".join(out)


REACH_COLUMNS = (
    ("onset_s", "onset (s)", 2, 1.0),
    ("movement_time_s", "movement time (s)", 2, 1.0),
    ("peak_speed_m_s", "peak speed (m/s)", 3, 1.0),
    ("time_to_peak_s", "time to peak (s)", 2, 1.0),
    ("time_to_peak_pct", "time to peak (%)", 0, 1.0),
    ("path_length_m", "path length (mm)", 1, 1000.0),
    ("path_length_ratio", "path-length ratio", 2, 1.0),
    ("sparc", "SPARC", 2, 1.0),
    ("log_dimensionless_jerk", "LDJ", 2, 1.0),
    ("movement_units", "movement units", 0, 1.0),
)


def _reach_table(kin: dict[str, Any]) -> str:
    reaches = kin.get("reaches") or []
    if not reaches:
        return "<p>No reach was found: the wrist speed never rose above the onset threshold.</p>"
    head = "".join(f"<th>{_e(label)}</th>" for _, label, _, _ in REACH_COLUMNS)
    rows = []
    for n, r in enumerate(reaches, 1):
        cells = "".join(_cell(f"reach-{n}-{key}", r.get(key), d, s)
                        for key, _, d, s in REACH_COLUMNS)
        rows.append(f"<tr><th>{n}</th>{cells}</tr>")
    settings = kin.get("settings") or {}
    onset = settings.get("onset_fraction", settings.get("threshold_fraction"))
    how = (f" Onset and offset where the speed crosses {onset * 100:g}% of the reach's peak."
           if isinstance(onset, int | float) else "")
    return (f'<table id="reach-table"><tr><th>reach</th>{head}</tr>{"".join(rows)}</table>'
            f"<p>SPARC: spectral arc length (smoother is closer to zero; a minimum-jerk reach "
            f"scores about -1.4 to -1.6). LDJ: log dimensionless jerk (smoother is closer to "
            f"zero). Movement units: speed peaks within the reach.{_e(how)}</p>")


def render_html(
    summary: dict[str, Any],
    columns: dict[str, np.ndarray],
    kin: dict[str, Any] | None,
    pngs: dict[str, bytes],
    run: Path,
) -> str:
    """The report as one HTML document with the PNG figures embedded as data URIs."""
    figures = []
    for n, (name, caption) in enumerate(FIGURES, 1):
        data = base64.b64encode(pngs[name]).decode("ascii")
        figures.append(
            f'<section id="fig-{name}"><h2>{_e(caption)}</h2><figure>'
            f'<img src="data:image/png;base64,{data}" alt="{_e(caption)}">'
            f"<figcaption>Figure {n}. {_e(caption)}.</figcaption></figure></section>"
        )
    title = f"Wrist motion report: {Path(str(summary.get('source', run))).name}"
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>"
        f'<header id="header"><h1>{_e(title)}</h1>{_meta(summary, run)}</header>'
        f"{_notes(summary, columns)}"
        f'<section id="summary"><h2>Summary</h2>{_summary_tables(summary, kin)}</section>'
        f'<section id="reaches"><h2>Reaches</h2>{_reach_table(kin)}</section>'
        f'{"".join(figures)}{_IMAGE_CHECK}</body></html>\n'
    )


def write_report(run_dir: str | Path) -> Path:
    """Write ``run_dir``/report.html and ``run_dir``/figures/*.png from the run's poses.csv and
    summary.json; returns the report's path."""
    run = Path(run_dir)
    columns, summary = read_run(run)
    kin = _kinematics(columns, summary)
    figures = build_figures(columns, kin)
    pngs = {name: rf.figure_png(fig) for name, fig in figures.items()}
    folder = run / "figures"
    folder.mkdir(exist_ok=True)
    for name, data in pngs.items():
        write_bytes_atomic(folder / f"{name}.png", data)
    out = run / "report.html"
    write_bytes_atomic(out, render_html(summary, columns, kin, pngs, run).encode("utf-8"))
    return out
