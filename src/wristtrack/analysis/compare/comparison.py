"""``wristtrack compare RUN_DIR REFERENCE``: agreement of a run with a reference system.

The reference (C3D, TRC, Qualisys TSV or a simulated truth.csv) becomes a pose per reference
frame (:mod:`.reference`), its markers low-passed first where asked (:mod:`.lowpass`); the
clocks are aligned coarsely on the speed profiles (:mod:`.align`) and then jointly with the
rigid registration camera -> lab (:mod:`.register`); the agreement is reported as validation
studies do (:mod:`.stats`). comparison.json keys follow DESIGN.md section 3 (a contract).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wristtrack.analysis.compare.align import CoarseAlignment, coarse_offset, speed
from wristtrack.analysis.compare.lowpass import butterworth, lowpass_markers
from wristtrack.analysis.compare.reference import (
    Interpolator,
    ReferencePoses,
    from_cluster,
    from_markers,
    from_truth,
    parse_mapping,
)
from wristtrack.analysis.compare.reference_noise import net_of, reference_noise
from wristtrack.analysis.compare.register import Registration, register
from wristtrack.analysis.compare.stats import bland_altman, icc21, range_difference, rmse
from wristtrack.analysis.kinematics import analyse
from wristtrack.analysis.range_of_motion import AXES
from wristtrack.errors import ConfigError, InputError
from wristtrack.geometry import quat_from_matrix, rotation_distance, wrist_angles
from wristtrack.hand import HandLayout
from wristtrack.io.poses import rows_to_poses
from wristtrack.io.run_folder import read_run


@dataclass(frozen=True)
class Comparison:
    """comparison.json's content plus the series the HTML page draws."""

    result: dict[str, Any]
    series: dict[str, np.ndarray]


def load_reference(
    reference: str | Path, markers: str | None, cluster: str | None, layout: np.ndarray | None,
    lowpass_hz: float | None = None,
) -> ReferencePoses:
    """The reference as poses: truth.csv as is, a marker file through --markers or --cluster,
    its trajectories low-passed at ``lowpass_hz`` first where given (compare/lowpass.py)."""
    path = Path(reference)
    if path.suffix.lower() == ".csv":
        if markers or cluster:
            raise ConfigError("a truth.csv reference takes neither --markers nor --cluster")
        if lowpass_hz is not None:
            raise ConfigError("a truth.csv reference is exact: --lowpass is for marker files")
        if not path.is_file():
            raise InputError(f"reference file {path} not found")
        return from_truth(path)
    from wristtrack.io.markers.read import read_markers

    if bool(markers) == bool(cluster):
        raise ConfigError(
            "say which reference markers to use: --cluster A,B,C (a rigid cluster on the back "
            "of the hand) or --markers WRIST=LABEL,... (our markers' labels), not both"
        )
    data = read_markers(path)
    if lowpass_hz is not None:
        data = lowpass_markers(data, lowpass_hz)
    if cluster:
        return from_cluster(data, [s.strip() for s in cluster.split(",") if s.strip()])
    if layout is None:
        raise InputError("the run's summary.json has no hand layout to map --markers onto")
    return from_markers(data, parse_mapping(markers or ""), layout)


def _num(x: Any) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def _ref_wrist(ref: ReferencePoses, x_t: np.ndarray) -> np.ndarray:
    """Our wrist as the reference sees it, at the reference's own samples (N,3); ``x_t`` is
    the wrist in the cluster's frame (a cluster reference only)."""
    if ref.kind != "cluster":
        return ref.p
    return ref.p + np.einsum("nij,j->ni", ref.R, x_t)


def _reach_agreement(cols: dict[str, np.ndarray], ref: ReferencePoses, reg: Registration
                     ) -> dict[str, Any]:
    """Peak speed and movement time of each reach, ours against the reference's (the reaches
    found in each by the same segmentation, paired by time overlap)."""
    ours = analyse(cols)["reaches"]
    ok = ref.valid
    t_ref_ours = (ref.times - reg.offset_s) / reg.ratio  # reference samples on our clock
    wrist = _ref_wrist(ref, reg.x_t)
    ref_cols = {"timestamp": t_ref_ours[ok], **{f"t{c}": wrist[ok, i] for i, c in
                                                 enumerate("xyz")}}
    theirs = analyse(ref_cols)["reaches"]
    pairs = []
    for r in ours:
        overlap = [min(r["offset_s"], s["offset_s"]) - max(r["onset_s"], s["onset_s"])
                   for s in theirs]
        if overlap and max(overlap) > 0:
            s = theirs[int(np.argmax(overlap))]
            pairs.append((r, s))
    out: dict[str, Any] = {"ours": len(ours), "reference": len(theirs), "paired": len(pairs),
                           "pairs": []}
    for r, s in pairs:
        out["pairs"].append({
            "onset_s": r["onset_s"],
            "peak_speed_m_s": [r["peak_speed_m_s"], s["peak_speed_m_s"]],
            "movement_time_s": [r["movement_time_s"], s["movement_time_s"]],
        })
    for key in ("peak_speed_m_s", "movement_time_s"):
        a = np.array([r[key] for r, _ in pairs], dtype=float)
        b = np.array([s[key] for _, s in pairs], dtype=float)
        ba = bland_altman(a, b)
        out[key] = {"bland_altman": ba, "icc": icc21(a, b)["icc"],
                    "mean_difference_pct": _num(100 * np.mean((a - b) / b)) if len(a) else None}
    return out


def compare(
    run_dir: str | Path,
    reference: str | Path,
    markers: str | None = None,
    cluster: str | None = None,
    fit_ratio: bool = True,
    max_lag_s: float | None = None,
    time_offset_s: float | None = None,
    lowpass_hz: float | None = None,
) -> Comparison:
    """Compare a run folder with a reference recording; see the module docstring.
    ``time_offset_s``: the clocks' offset when it is known (systems synchronised by a trigger):
    no alignment is attempted, which also allows a static trial. ``lowpass_hz``: the reference's
    marker trajectories low-passed at this cutoff first, as labs filter them (None: as
    recorded)."""
    cols, summary = read_run(run_dir)
    side = (summary.get("conventions") or {}).get("side", "right")
    layout = None
    if summary.get("hand_layout"):
        layout = HandLayout.from_dict(summary["hand_layout"], source="summary.json").points
    ref = load_reference(reference, markers, cluster, layout, lowpass_hz)
    R_ch, t_ch = rows_to_poses(cols)
    t = cols["timestamp"]
    ok = np.isfinite(t_ch).all(axis=1) & np.isfinite(R_ch).all(axis=(1, 2))
    if ok.sum() < 10:
        raise InputError(f"{run_dir}: fewer than 10 frames with a pose; nothing to compare")

    if time_offset_s is None:
        # Before the registration the cluster's origin stands in for the wrist.
        coarse = coarse_offset(t, speed(t, np.where(ok[:, None], t_ch, np.nan)), ref.times,
                               speed(ref.times, _ref_wrist(ref, np.zeros(3))), max_lag_s)
    else:
        coarse = CoarseAlignment(float(time_offset_s), float("nan"))
    interp = Interpolator(ref)
    idx = np.flatnonzero(ok)
    reg = register(t[idx], R_ch[idx], t_ch[idx], interp, coarse.offset_s,
                   ref.kind == "cluster", fit_ratio, fit_offset=time_offset_s is None)

    # Every frame both systems saw counts in the agreement, not only those the fit kept.
    tau = reg.ref_times(t)
    both = ok & interp.usable(tau)
    k = np.flatnonzero(both)
    R_ref, p_ref = interp(tau[k])
    R_lab, p_lab = reg.to_lab(R_ch[k], t_ch[k])
    pos_err = (p_lab - (p_ref + R_ref @ reg.x_t)) * 1e3
    R_ref_hand = R_ref @ reg.X_R
    rot_err = np.degrees(rotation_distance(R_lab, R_ref_hand)) if ref.has_rotation else None
    noise = None
    if ref.model is not None:
        sos = None if lowpass_hz is None else butterworth(lowpass_hz, ref.rate)
        noise = reference_noise(ref.model, ref.fit_rms_mm, reg.x_t, tau[k], ref.times[0],
                                ref.rate, sos, ref.fit_markers)
    pos_rmse = rmse(pos_err)
    rot_rmse = rmse(rot_err) if rot_err is not None else None

    ours_deg = np.column_stack([cols[f"{a}_deg"][k] for a in AXES])
    ref_deg = np.full_like(ours_deg, np.nan)
    neutral_note = None
    if ref.has_rotation:
        t0 = t[idx[0]]  # W0 = our hand frame at our first estimate
        if interp.usable(np.array([reg.ref_times(t0)]))[0]:
            R_n = interp(np.array([reg.ref_times(t0)]))[0][0] @ reg.X_R
            neutral_note = "the reference's own hand pose at our W0 instant"
        else:
            R_n = reg.R_lc @ R_ch[idx[0]]
            neutral_note = "our W0 registered into the lab (the reference starts later)"
        ref_deg = np.degrees(wrist_angles(np.swapaxes(R_n, -1, -2)[None] @ R_ref_hand, side))

    result: dict[str, Any] = {
        "run": str(run_dir),
        "reference": {
            "path": str(reference), "kind": ref.kind, "rate_hz": ref.rate, "units": ref.units,
            "labels": ref.labels, "frames": len(ref.times), "frames_with_pose":
            int(ref.valid.sum()), "lowpass_hz": lowpass_hz, "notes": list(ref.notes),
            "rigid_fit_rms_mm": _num(np.nanmedian(ref.fit_rms_mm)) if ref.valid.any() else None,
        },
        "time_offset_s": reg.offset_s,
        "time_offset_sigma_s": reg.sigma["offset_s"],
        "clock_ratio": reg.ratio,
        "clock_ratio_sigma": reg.sigma["ratio"],
        "coarse_offset_s": coarse.offset_s,
        "time_offset_given": time_offset_s is not None,
        "speed_correlation": _num(coarse.peak),
        "frames_compared": int(len(k)),
        "frames_registered": int(reg.used.sum()),
        "pos_rmse_mm": pos_rmse,
        "rot_rmse_deg": rot_rmse,
        # the reference's own noise where compared, and our error net of it (reference_noise.py)
        "reference_noise": None if noise is None else noise.as_dict(),
        "pos_rmse_net_mm": None if noise is None else net_of(pos_rmse, noise.position_mm),
        "rot_rmse_net_deg": None if noise is None else net_of(rot_rmse, noise.rotation_deg),
        "rom_error_deg": {},
        "bland_altman": {},
        "icc": {},
        "icc_ci95": {},
        "range_of_motion_deg": {},
        "registration": {
            "rotation": reg.R_lc.tolist(),
            "translation": reg.t_lc.tolist(),
            "quaternion_wxyz": quat_from_matrix(reg.R_lc).tolist(),
            "frame": "reference lab <- camera: x_lab = rotation x_cam + translation (metres)",
            "hand_centre_cam_m": reg.hand_centre_cam.tolist(),
            "sigma": reg.sigma,
            "iterations": reg.iterations,
        },
        "angles": {
            "convention": "ISB wrist angles, as in poses.csv; each system relative to its own "
            "neutral",
            "reference_neutral": neutral_note,
            "difference": "ours - reference",
        },
    }
    if ref.kind == "cluster":
        result["cluster_offset"] = {
            "rotation": reg.X_R.tolist(), "translation": reg.x_t.tolist(),
            "frame": "cluster <- our hand frame (metres)",
        }
    for j, axis in enumerate(AXES):
        ba = bland_altman(ours_deg[:, j], ref_deg[:, j])
        result["bland_altman"][axis] = {
            "bias_deg": ba["bias"], "sd_deg": ba["sd"], "loa_low_deg": ba["loa_low"],
            "loa_high_deg": ba["loa_high"], "n": ba["n"],
        }
        icc = icc21(ours_deg[:, j], ref_deg[:, j])
        result["icc"][axis] = icc["icc"]
        result["icc_ci95"][axis] = icc["ci95"]
        rom = range_difference(ours_deg[:, j], ref_deg[:, j])
        result["rom_error_deg"][axis] = rom["error"]
        result["range_of_motion_deg"][axis] = {"ours": rom["range_ours"],
                                               "reference": rom["range_ref"]}
    result["reaches"] = _reach_agreement(cols, ref, reg)
    result["warnings"] = _warnings(result, len(idx))
    ref_speed_t = (ref.times - reg.offset_s) / reg.ratio
    series = {
        "t": t[k], "ours_deg": ours_deg, "ref_deg": ref_deg, "pos_err_mm": pos_err,
        "rot_err_deg": rot_err if rot_err is not None else np.full(len(k), np.nan),
        "speed_t": t, "speed_ours": speed(t, np.where(ok[:, None], t_ch, np.nan)),
        "ref_speed_t": ref_speed_t, "ref_speed": speed(ref.times, _ref_wrist(ref, reg.x_t)),
        "ref_speed_t_coarse": ref.times - coarse.offset_s,
    }
    return Comparison(result, series)


def comparison_json(comparison: Comparison) -> str:
    """The text of comparison.json (non-finite numbers as null: JSON has no NaN)."""
    return json.dumps(_finite(comparison.result), indent=2, allow_nan=False) + "\n"


# Two crystal clocks differ by well under 0.1 %; a fit further off has aligned the wrong
# things (a lost track, a different take).
RATIO_PLAUSIBLE = 1e-3
# The reference's noise at this share of an RMSE or more: the figure says more about it than us.
NOISE_MOST = 0.7


def _warnings(result: dict[str, Any], frames_with_pose: int) -> list[str]:
    """Plain-language doubts about this comparison (empty when there are none)."""
    out = []
    if abs(result["clock_ratio"] - 1.0) > RATIO_PLAUSIBLE:
        out.append(f"clock ratio {result['clock_ratio']:.4f} is implausible for two crystal "
                   "clocks: the alignment has probably failed (try --no-clock-ratio, --max-lag)")
    if result["speed_correlation"] is not None and result["speed_correlation"] < 0.5:
        out.append(f"the speed profiles correlate poorly ({result['speed_correlation']:.2f}): "
                   "check that both recordings hold the same movement")
    if result["frames_registered"] < 0.8 * result["frames_compared"]:
        out.append(f"the registration kept only {result['frames_registered']} of "
                   f"{result['frames_compared']} frames: many tracking outliers")
    noise = result.get("reference_noise")
    if noise and result["rot_rmse_deg"] and noise["rotation_deg"] >= NOISE_MOST * result[
            "rot_rmse_deg"]:
        out.append(f"the reference's own noise ({noise['rotation_deg']:.3f} deg of orientation "
                   f"from {noise['marker_mm']:.3f} mm per marker coordinate) is most of the "
                   "orientation RMSE: low-pass its markers (--lowpass) or use a more precise "
                   "reference")
    if result["frames_compared"] < 0.5 * frames_with_pose:
        out.append(f"only {result['frames_compared']} of our {frames_with_pose} frames with a "
                   "pose fall inside the reference's recording")
    return out


def _finite(obj: Any) -> Any:
    """The result with every non-finite number as null (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def format_comparison(result: dict[str, Any]) -> str:
    """A few lines for the terminal."""

    def f(x, d=2):
        return "n/a" if x is None else f"{x:.{d}f}"

    lines = [
        f"time offset   {f(result['time_offset_s'] * 1e3, 2)} ms "
        f"(+- {f(result['time_offset_sigma_s'] * 1e3, 2)}), clock ratio "
        f"{result['clock_ratio']:.6f} (+- {result['clock_ratio_sigma']:.1e})",
        f"frames        {result['frames_compared']} compared, {result['frames_registered']} "
        "in the registration",
        f"position RMSE {f(result['pos_rmse_mm'])} mm, orientation RMSE "
        f"{f(result['rot_rmse_deg'])} deg",
    ]
    noise = result.get("reference_noise")
    if noise:
        lines.append(
            f"reference noise {f(noise['marker_mm'], 3)} mm per marker coordinate: "
            f"{f(noise['position_mm'], 3)} mm, {f(noise['rotation_deg'], 3)} deg where compared; "
            f"net of it {f(result['pos_rmse_net_mm'])} mm, {f(result['rot_rmse_net_deg'])} deg")
    for axis in AXES:
        ba = result["bland_altman"][axis]
        lines.append(
            f"{axis:<10} bias {f(ba['bias_deg'])} deg, LoA [{f(ba['loa_low_deg'])}, "
            f"{f(ba['loa_high_deg'])}], ICC(2,1) {f(result['icc'][axis], 3)}, RoM error "
            f"{f(result['rom_error_deg'][axis])} deg"
        )
    lines += [f"warning: {w}" for w in result.get("warnings", [])]
    return "\n".join(lines)

