"""Agreement statistics as validation studies report them: Bland-Altman bias and 95 % limits of
agreement (Bland & Altman 1986: bias +- 1.96 SD of the differences), ICC(2,1) (Shrout & Fleiss
1979: two-way random effects, absolute agreement, single measurement) from pingouin, RMSE.

pingouin is an optional extra (``pip install 'wristtrack[validation]'``); it is the kept
implementation of the ICC family, with its confidence interval.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from wristtrack.errors import ConfigError

LOA_Z = 1.96


def bland_altman(ours: np.ndarray, ref: np.ndarray) -> dict[str, float | int | None]:
    """Bias (mean of ours - ref), SD of the differences (n - 1) and the 95 % limits of
    agreement over the pairs where both are finite; None where fewer than two pairs."""
    a, b = np.asarray(ours, dtype=float), np.asarray(ref, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    d = a[ok] - b[ok]
    if d.size < 2:
        return {"bias": None, "sd": None, "loa_low": None, "loa_high": None, "n": int(d.size)}
    bias, sd = float(d.mean()), float(d.std(ddof=1))
    return {"bias": bias, "sd": sd, "loa_low": bias - LOA_Z * sd, "loa_high": bias + LOA_Z * sd,
            "n": int(d.size)}


def _pingouin():
    try:
        import pingouin
    except ImportError:
        raise ConfigError(
            "the ICC needs the pingouin package: pip install 'wristtrack[validation]'"
        ) from None
    return pingouin


def icc2_1(ratings: np.ndarray) -> dict[str, Any]:
    """ICC(2,1) of a (targets, raters) table with its 95 % CI, from pingouin.intraclass_corr
    ('ICC(A,1)', formerly 'ICC2'). Rows with a NaN are left out; None with fewer than five
    complete targets or no spread at all (the ICC is undefined then)."""
    x = np.asarray(ratings, dtype=float)
    x = x[np.isfinite(x).all(axis=1)]
    n, k = x.shape
    if n < 5 or np.ptp(x) == 0:
        return {"icc": None, "ci95": None, "n": n}
    import pandas as pd  # a pingouin dependency

    pg = _pingouin()
    frame = pd.DataFrame({
        "target": np.repeat(np.arange(n), k),
        "rater": np.tile(np.arange(k), n),
        "rating": x.reshape(-1),
    })
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pandas FutureWarnings from inside pingouin
        table = pg.intraclass_corr(frame, targets="target", raters="rater", ratings="rating")
    # pingouin >= 0.7 names it ICC(A,1) (McGraw & Wong), older versions ICC2.
    table = table.set_index("Type")
    row = table.loc["ICC(A,1)" if "ICC(A,1)" in table.index else "ICC2"]
    ci = [float(c) for c in np.asarray(row["CI95"], dtype=float).reshape(-1)[:2]]
    return {"icc": float(row["ICC"]), "ci95": ci, "n": n}


def icc21(ours: np.ndarray, ref: np.ndarray) -> dict[str, Any]:
    """ICC(2,1) of two raters, our system and the reference, over paired targets."""
    return icc2_1(np.column_stack([np.asarray(ours, float), np.asarray(ref, float)]))


def rmse(x: np.ndarray) -> float | None:
    """Root mean square of the finite rows' norms (x (N,) or (N,D))."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    ok = np.isfinite(x).all(axis=1)
    if not ok.any():
        return None
    return float(np.sqrt(np.mean(np.sum(x[ok] ** 2, axis=1))))


def range_difference(ours: np.ndarray, ref: np.ndarray) -> dict[str, float | None]:
    """Range of motion (max - min) of each over the paired finite samples, and ours - ref."""
    a, b = np.asarray(ours, dtype=float), np.asarray(ref, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():
        return {"range_ours": None, "range_ref": None, "error": None}
    ra, rb = float(np.ptp(a[ok])), float(np.ptp(b[ok]))
    return {"range_ours": ra, "range_ref": rb, "error": ra - rb}
