"""The study table (study.csv) and study report (study.html) of ``wristtrack batch``.

One row per recording: whether it was tracked (``ok``), failed (with the error's one line),
was already done (``skipped``, figures read from its summary.json) or is still ``pending`` (an
interrupted batch); its frames, frames tracked, range of motion per anatomical axis, peak wrist
speed and duration. Both files are replaced atomically, so a batch stopped at any moment leaves
a complete, readable table of what finished.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import math
from pathlib import Path
from typing import Any

from wristtrack.analysis.summary import AXES
from wristtrack.io.atomic import write_text_atomic

COLUMNS = (
    "recording", "status", "error", "frames", "frames_tracked",
    *(f"{axis}_range_deg" for axis in AXES), "peak_speed_m_s", "duration_s",
    "hand_layout",  # where the layout came from: hand.json, still start or surveyed
)
STATUSES = ("ok", "failed", "skipped", "pending")


def row_from_summary(name: str, status: str, summary: dict[str, Any]) -> dict[str, Any]:
    """A study row from a run's summary.json."""
    rom = summary.get("range_of_motion", {})
    frames = summary.get("frames", {})
    row: dict[str, Any] = {
        "recording": name, "status": status, "error": "",
        "frames": frames.get("total"), "frames_tracked": frames.get("tracked"),
        "peak_speed_m_s": summary.get("peak_speed_m_s"), "duration_s": summary.get("duration_s"),
        "hand_layout": (summary.get("settings") or {}).get("hand_layout_from"),
    }
    for axis in AXES:
        row[f"{axis}_range_deg"] = rom.get(axis, {}).get("range_deg")
    return row


def row_without_run(name: str, status: str, error: str = "") -> dict[str, Any]:
    """A study row with no figures (failed or pending)."""
    row = dict.fromkeys(COLUMNS)
    row.update(recording=name, status=status, error=one_line(error))
    return row


def one_line(text: str) -> str:
    """The text on a single line (an error message must not break the table)."""
    return " ".join(str(text).split())


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return str(value)


def write_study_csv(path: str | Path, rows: list[dict[str, Any]]) -> None:
    """study.csv, atomically."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in COLUMNS])
    write_text_atomic(path, buf.getvalue())


def read_study_csv(path: str | Path) -> list[dict[str, str]]:
    """study.csv rows as dicts of strings."""
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _rom_chart(rows: list[dict[str, Any]]) -> str | None:
    """Grouped bars of the RoM per recording as a base64 PNG, or None with nothing to plot."""
    plotted = [r for r in rows if any(r.get(f"{a}_range_deg") is not None for a in AXES)]
    if not plotted:
        return None
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    width = 0.8 / len(AXES)
    fig = Figure(figsize=(max(4.0, 0.6 * len(plotted) + 2.0), 3.2), dpi=100)
    ax = fig.add_subplot()
    for k, axis in enumerate(AXES):
        values = [r.get(f"{axis}_range_deg") or 0.0 for r in plotted]
        ax.bar([i + (k - 1) * width for i in range(len(plotted))], values, width, label=axis)
    ax.set_xticks(range(len(plotted)))
    ax.set_xticklabels([r["recording"] for r in plotted], rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("range of motion (deg)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    png = io.BytesIO()
    fig.savefig(png, format="png")
    return base64.b64encode(png.getvalue()).decode("ascii")


def write_study_html(path: str | Path, rows: list[dict[str, Any]], title: str) -> None:
    """study.html: the study table and a RoM bar chart, self-contained (the chart inline)."""
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    head = "".join(f"<th>{html.escape(c)}</th>" for c in COLUMNS)
    body = []
    for row in rows:
        cls = html.escape(str(row["status"]))
        cells = "".join(f"<td>{html.escape(_cell(row.get(c)))}</td>" for c in COLUMNS)
        body.append(f'<tr class="{cls}">{cells}</tr>')
    chart = _rom_chart(rows)
    figure = (
        f'<img alt="range of motion per recording" src="data:image/png;base64,{chart}">'
        if chart else "<p>No recording was tracked, so there is no range of motion to plot.</p>"
    )
    summary = ", ".join(f"{n} {s}" for s, n in counts.items() if n)
    text = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; }}
table {{ border-collapse: collapse; font-size: 0.85em; }}
th, td {{ border: 1px solid #bbb; padding: 0.25em 0.5em; text-align: left; }}
tr.failed td {{ background: #fde2e2; }}
tr.pending td {{ color: #777; }}
</style></head><body>
<h1>{html.escape(title)}</h1>
<p>{len(rows)} recordings: {html.escape(summary)}. Ranges of motion in degrees (ISB wrist
angles relative to the first neutral pose), peak wrist speed in m/s, duration in s.</p>
{figure}
<table><thead><tr>{head}</tr></thead><tbody>
{chr(10).join(body)}
</tbody></table></body></html>
"""
    write_text_atomic(path, text)
