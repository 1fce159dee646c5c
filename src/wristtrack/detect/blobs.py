"""Blob measurements, vectorised over all blobs of a frame: centre, shape, depth, splitting.

Every blob is measured in a window of the full-resolution frame (all windows of a frame have one
size, so the work is a few NumPy operations on a stack, not a Python loop per blob).

Centre. Each pixel is weighted by its *blueness* t = (p - b).(m - b) / |m - b|^2, the position
of its colour p on the segment from the local background colour b (mean of a ring around the
blob) to the marker colour m (mean of the blob): 0 on the background, 1 on the marker and,
because optics and anti-aliasing mix colours linearly, the fraction of the pixel the marker
covers in between, free of the half-pixel steps of a thresholded mask; they are scaled so the
bluest pixel is 1 (sum = area in pixels). The centre is the centroid of these weights with the
background's taken out: clipped at 0 and, below CENTRE_KNEE, squared (w^2 / knee). The plain
weighted centroid is unbiased for any centrally symmetric footprint, but every background pixel
of the window adds its noise at its distance from the centre, and those dominated it: against
the truth, sharp rendered blobs were 0.042 px off, JPEG ones 0.098, oblique dim ones at the
extremes of a movement with every camera effect 0.21-0.31 (3 seeds). The knee takes the
background's weights to ~0 and leaves the marker's own pixels linear (all squared, a highlight's
bite out of the marker would count twice): 0.015 / 0.066 / 0.16-0.27 px, still unbiased for
symmetric footprints (a squared weight is as symmetric as the weight).
Where the background is two surfaces (a marker on the hand's edge: skin and table; a marker at
an occluder's edge) each pixel is unmixed against the one that explains its colour better. A
glossy marker's highlight (white added to the marker's colour) is read along the part of the
colour axis that white does not change, and where it clipped the colour, at the marker's own
level (:func:`discount_highlights`).

Shape. From the weighted moments: the moment-equivalent ellipse (full axes 4 sigma), and a
skewness, the square root of Mardia's multivariate skewness (root sum of squares of the third
moments in whitened coordinates). Every projected disc is centrally symmetric (skew 0), and so
are two equal touching discs and a motion-blurred disc; a disc cut by an occluder is not: hiding
2 / 6 / 9 / 20 % of a disc gives a skew of about 0.06 / 0.15 / 0.21 / 0.38 (and moves its
centroid by 0.02 / 0.05 / 0.08 / 0.17 radii). The skewness is read from the weights clipped to
[0, 1] and zeroed below 0.2, so background noise around small blobs does not swamp it.

Depth. Trimmed mean of the valid (non-zero) depth pixels of the blob's interior (blueness above
0.6: mostly marker, so registration error at its edge does not mix in the surface around it).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

DEPTH_CORE = 0.6  # blob pixels used for depth: blueness above this
HIGHLIGHT_MIN_BLUENESS = 0.25  # a highlight's pixel is still this much marker by its chroma
HIGHLIGHT_SKIRT_EXCESS = 10.0  # grey levels: a highlight's skirt, next to its core
HIGHLIGHT_SKIRT_PX = 2  # how far from the core the skirt is looked for
NEAR_CLIP = 200  # a channel this bright in a highlight: its chroma is lost
ENCLOSED_PX = 3  # a clipped pixel with the marker this near on both sides lies on the marker


def gather(img: np.ndarray, y0: np.ndarray, x0: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Stack of windows (n, sy, sx, ...) of ``img`` at top-left corners (y0, x0) (n,); every
    window must lie inside the image."""
    sy, sx = size
    out = np.empty((len(y0), sy, sx, *img.shape[2:]), img.dtype)
    for k, (y, x) in enumerate(zip(y0.tolist(), x0.tolist(), strict=True)):
        out[k] = img[y : y + sy, x : x + sx]
    return out


def upsample2(a: np.ndarray) -> np.ndarray:
    """(n, h, w) -> (n, 2h, 2w), each pixel repeated 2 x 2 (half-res mask to full res)."""
    return np.repeat(np.repeat(a, 2, axis=1), 2, axis=2)


@functools.cache
def _basis(sy: int, sx: int) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Powers 0..3 of pixel coordinates relative to the window centre (for conditioning):
    (sx, 4) of x and (4, sy) of y, so the raw moments of a window w are Y @ w @ X (two small
    matrix products per window, cheaper than one product with all the monomials); and that
    centre."""
    cy, cx = (sy - 1) / 2, (sx - 1) / 2
    x = np.arange(sx, dtype=np.float64) - cx
    y = np.arange(sy, dtype=np.float64) - cy
    X = np.stack([np.ones_like(x), x, x * x, x**3], 1)
    Y = np.stack([np.ones_like(y), y, y * y, y**3], 0)
    return X, Y, cx, cy


# (y power, x power) of the raw moments 1, x, y, x^2, xy, y^2, x^3, x^2y, xy^2, y^3
_POWERS = (np.array([0, 0, 1, 0, 1, 2, 0, 1, 2, 3]), np.array([0, 1, 0, 2, 1, 0, 3, 2, 1, 0]))


@dataclass
class Shapes:
    """Weighted-moment shape of n blobs; coordinates in their windows."""

    mass: np.ndarray  # sum of weights (area in px for normalised blueness)
    cx: np.ndarray
    cy: np.ndarray
    major: np.ndarray  # full axes of the moment-equivalent ellipse, px
    minor: np.ndarray
    angle: np.ndarray  # major-axis direction, rad (x right, y down)
    skew: np.ndarray


def _central(row: list[float]):
    """Mass, centroid, second and third central moments (per unit mass) from one row of raw
    moments of _basis. Plain floats: a handful of blobs is far cheaper in scalar Python than
    in NumPy calls on arrays of that length."""
    m00, x, y, xx, xy, yy, xxx, xxy, xyy, yyy = row
    if not m00 > 0:
        return m00, 0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)
    mx, my = x / m00, y / m00
    xx, xy, yy, xxx, xxy, xyy, yyy = (v / m00 for v in (xx, xy, yy, xxx, xxy, xyy, yyy))
    second = (xx - mx * mx, xy - mx * my, yy - my * my)
    third = (xxx - 3 * mx * xx + 2 * mx**3,
             xxy - 2 * mx * xy - my * xx + 2 * mx * mx * my,
             xyy - 2 * my * xy - mx * yy + 2 * mx * my * my,
             yyy - 3 * my * yy + 2 * my**3)
    return m00, mx, my, second, third


def _principal(a: float, b: float, c: float) -> tuple[float, float, float]:
    """Eigenvalues (l1 >= l2) and major-axis angle of the covariance [[a, b], [b, c]]."""
    half_tr = 0.5 * (a + c)
    root = math.sqrt(max(half_tr * half_tr - (a * c - b * b), 0.0))
    return max(half_tr + root, 1e-12), max(half_tr - root, 1e-12), 0.5 * math.atan2(2 * b, a - c)


def _skewness(second, third) -> float:
    """Square root of Mardia's skewness: root sum of squares of the third moments of the
    whitened coordinates (third moments rotated to the principal axes, over the sigmas)."""
    l1, l2, angle = _principal(*second)
    m30, m21, m12, m03 = third
    co, si = math.cos(angle), math.sin(angle)
    ppp = co**3 * m30 + 3 * co * co * si * m21 + 3 * co * si * si * m12 + si**3 * m03
    qqq = -(si**3) * m30 + 3 * si * si * co * m21 - 3 * si * co * co * m12 + co**3 * m03
    ppq = (-(co * co * si) * m30 + (co**3 - 2 * co * si * si) * m21
           + (2 * co * co * si - si**3) * m12 + co * si * si * m03)
    pqq = (co * si * si * m30 + (si**3 - 2 * co * co * si) * m21
           + (co**3 - 2 * co * si * si) * m12 + co * co * si * m03)
    s1, s2 = math.sqrt(l1), math.sqrt(l2)
    return math.sqrt((ppp / s1**3) ** 2 + 3 * (ppq / (s1 * s1 * s2)) ** 2
                     + 3 * (pqq / (s1 * s2 * s2)) ** 2 + (qqq / s2**3) ** 2)


# Skewness is read from the weights clipped to [0, 1] and zeroed below this: third moments
# weigh far pixels by distance cubed, so the zero-mean noise of the background around a small
# blob would otherwise dominate them.
SKEW_FLOOR = 0.2
# Below this blueness the centre's weights fall off as its square (module doc, Centre).
CENTRE_KNEE = 0.7


def centre_weights(w: np.ndarray) -> np.ndarray:
    """The weights of the centre (module doc): ``w`` clipped at 0, below CENTRE_KNEE squared
    (w^2 / CENTRE_KNEE, continuous at the knee)."""
    c = np.maximum(w, 0.0)
    return np.where(c < CENTRE_KNEE, c * c / CENTRE_KNEE, c)


def shapes(w: np.ndarray) -> Shapes:
    """Shapes of a stack of weight windows (n, sy, sx): the mass, axes and angle from the
    weights, the centre from :func:`centre_weights`, the skew from the firm weights."""
    n, sy, sx = w.shape
    X, Y, ox, oy = _basis(sy, sx)
    both = np.empty((3 * n, sy, sx))
    both[:n] = w
    np.minimum(both[:n], 1.0, out=both[n:2 * n])
    both[n:2 * n][both[n:2 * n] < SKEW_FLOOR] = 0.0
    both[2 * n:] = centre_weights(w)
    # raw moments: the weights, the firm weights, the centre's weights
    rows = (Y @ (both @ X))[:, _POWERS[0], _POWERS[1]].tolist()
    out = np.empty((7, n))
    for k in range(n):
        m00, mx, my, second, _ = _central(rows[k])
        l1, l2, angle = _principal(*second)
        _, _, _, second_f, third_f = _central(rows[n + k])
        skew = _skewness(second_f, third_f) if rows[n + k][0] > 0 else 0.0
        if rows[2 * n + k][0] > 0:
            _, mx, my, _, _ = _central(rows[2 * n + k])
        out[:, k] = (m00, mx + ox, my + oy, 4 * math.sqrt(l1), 4 * math.sqrt(l2), angle, skew)
    return Shapes(*out)


def blueness(patch: np.ndarray, m: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """t = (p - b).(m - b) / |m - b|^2 for a stack of BGR windows (n, sy, sx, 3) and per-window
    marker and background colours (n, 3), and each pixel's brightness B + G + R (for
    :func:`discount_highlights`, from the same product); both float32 (n, sy, sx)."""
    d = m - b
    g = d / np.maximum((d * d).sum(1), 1e-9)[:, None]
    n, sy, sx, _ = patch.shape
    G = np.ones((n, 3, 2), np.float32)
    G[:, :, 0] = g
    tb = patch.reshape(n, -1, 3).astype(np.float32) @ G
    t = tb[:, :, 0].reshape(n, sy, sx) - (b * g).sum(1).astype(np.float32)[:, None, None]
    return t, tb[:, :, 1].reshape(n, sy, sx)


def discount_highlights(t: np.ndarray, brightness: np.ndarray, patch: np.ndarray, m: np.ndarray,
                        b: np.ndarray, min_excess: float) -> np.ndarray:
    """Blueness (n, sy, sx) with the markers' specular highlights discounted.

    A glossy marker mirrors the lamp: by the dichromatic reflection model its pixels add the
    light's colour, white, to the marker's. Such a pixel lies off the background-marker line,
    its blueness falls toward 0, and the highlight becomes a bite out of the marker that pulls
    the centroid away from it (0.1-0.5 px). Three parts:

    - the core: where a pixel is brighter along white than any mix of ``b`` and ``m`` by more
      than ``min_excess`` grey levels, its blueness is read along the part of ``m - b``
      orthogonal to white, which a white highlight does not change (not everywhere: that
      direction is shorter, so its noise is about 20 % higher; under JPEG, whose chroma is
      coarse, a lower threshold everywhere made blobs 0.081 -> 0.092 px off);
    - the skirt: the spot fades into the marker, and its outer pixels, too dim for
      ``min_excess``, still lose blueness (0.7 % per grey level of white on a blue marker
      against skin). Within HIGHLIGHT_SKIRT_PX of a core pixel the threshold is
      HIGHLIGHT_SKIRT_EXCESS: hysteresis, as an edge detector links weak edges to strong ones;
    - the clipped centre: a channel near the top of the range (NEAR_CLIP; white balance and
      compression bring clipped channels below 255) has lost the chroma the white-free reading
      needs. A highlight lies on the marker, so such a pixel with the marker on both sides of
      it (within ENCLOSED_PX, along a row or a column) is taken at the marker's own level (the
      median of its firm pixels).

    On the rendered recordings (seed 0) blobs under the specular effect alone were 0.077 px
    off with the core alone, 0.060 with the skirt, 0.028 with the clipped centre too (clean:
    0.021); with every effect 0.166 -> 0.134 px; JPEG alone and Bayer alone unchanged.
    """
    d = (m - b).astype(np.float32)
    bf = b.astype(np.float32)
    total = d.sum(1)
    # brightness along white beyond the b-m mix of the pixel's blueness, in grey levels x sqrt 3
    excess = brightness - t * total[:, None, None] - bf.sum(1)[:, None, None]
    core = excess > np.float32(min_excess * math.sqrt(3.0))
    # the rest only for the windows with a core (a whole-frame search holds many without)
    k = np.flatnonzero(core.reshape(len(core), -1).any(axis=1))
    if k.size == 0:
        return t
    out = t.copy()
    out[k] = _discounted(t[k], patch[k], d[k], bf[k], total[k], excess[k], core[k])
    return out


def _discounted(t: np.ndarray, patch: np.ndarray, d: np.ndarray, bf: np.ndarray,
                total: np.ndarray, excess: np.ndarray, core: np.ndarray) -> np.ndarray:
    """discount_highlights on windows that each hold a highlight's core: the skirt, the
    white-free reading and the clipped centre (its doc)."""
    hot = core | ((excess > np.float32(HIGHLIGHT_SKIRT_EXCESS * math.sqrt(3.0)))
                  & _near(core, HIGHLIGHT_SKIRT_PX))
    chroma = d - total[:, None] / 3  # m - b without its white component
    g = chroma / np.maximum((chroma * d).sum(1), 1e-9)[:, None]
    n, sy, sx, _ = patch.shape
    t_white_free = (patch.reshape(n, -1, 3).astype(np.float32) @ g[:, :, None]).reshape(
        n, sy, sx) - (bf * g).sum(1)[:, None, None]
    # (the channels' maximum pairwise: numpy's max over a last axis of 3 is ~10x slower)
    brightest = np.maximum(np.maximum(patch[..., 0], patch[..., 1]), patch[..., 2])
    clipped = hot & (brightest >= NEAR_CLIP)
    # Skin in brighter light than the ring's mean is bright too, but its chroma is skin's.
    hot &= t_white_free > HIGHLIGHT_MIN_BLUENESS
    out = np.where(hot, t_white_free, t)
    k = np.flatnonzero(clipped.reshape(n, -1).any(axis=1))
    if k.size:
        out[k] = _fill_clipped(out[k], clipped[k])
    return out


def _fill_clipped(t: np.ndarray, clipped: np.ndarray) -> np.ndarray:
    """``t`` (n, sy, sx) with the ``clipped`` pixels that have the marker's firm pixels on both
    sides raised to the marker's level (discount_highlights)."""
    firm = t > 0.5
    enclosed = clipped & (
        (_seen(firm, ENCLOSED_PX, 1, 1) & _seen(firm, ENCLOSED_PX, 1, -1))
        | (_seen(firm, ENCLOSED_PX, 2, 1) & _seen(firm, ENCLOSED_PX, 2, -1)))
    out = t.copy()
    for k in np.flatnonzero(enclosed.any(axis=(1, 2))):
        level = np.median(t[k][firm[k]])
        out[k] = np.where(enclosed[k], np.maximum(t[k], level), t[k])
    return out


def _near(mask: np.ndarray, reach: int) -> np.ndarray:
    """Pixels of a stack of masks (n, sy, sx) within ``reach`` px of a set one along a row or a
    column (the set ones included)."""
    out = mask.copy()
    for axis in (1, 2):
        for step in (1, -1):
            out |= _seen(mask, reach, axis, step)
    return out


def _seen(mask: np.ndarray, reach: int, axis: int, step: int) -> np.ndarray:
    """Whether a set pixel of ``mask`` (n, sy, sx) lies 1 to ``reach`` px before (``step`` 1)
    or after (-1) each pixel along ``axis`` (1: down the column, 2: along the row)."""
    out = np.zeros_like(mask)
    size = mask.shape[axis]
    for s in range(1, min(reach, size - 1) + 1):
        src, dst = [slice(None)] * 3, [slice(None)] * 3
        src[axis], dst[axis] = ((slice(0, size - s), slice(s, size)) if step > 0
                                else (slice(s, size), slice(0, size - s)))
        out[tuple(dst)] |= mask[tuple(src)]
    return out


def trimmed_depth(depth: np.ndarray, mask: np.ndarray, trim: tuple[float, float]) -> np.ndarray:
    """Per window (n, ...) mean of the non-zero raw depths where ``mask`` is set, between the
    ``trim`` quantiles (raw units, float); NaN where no pixel is valid."""
    n = depth.shape[0]
    d = depth.reshape(n, -1)
    row, col = np.nonzero(mask.reshape(n, -1) & (d > 0))
    # one sort of (window, depth) keys orders every window's depths at once
    key = np.sort(row.astype(np.int64) << 16 | d[row, col])
    v = np.concatenate([[0], np.cumsum(key & 0xFFFF)])
    k = np.bincount(row, minlength=n)
    start = np.concatenate([[0], np.cumsum(k)[:-1]])
    lo = (trim[0] * k).astype(np.int64)
    hi = np.ceil(trim[1] * k).astype(np.int64)
    bad = hi <= lo
    lo[bad], hi[bad] = 0, k[bad]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (v[start + hi] - v[start + lo]) / (hi - lo)
    z[k == 0] = np.nan
    return z


def split_pair(w: np.ndarray, cx: float, cy: float, angle: float, waist_ratio: float,
               min_mass_ratio: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Try to cut an elongated blob (weights ``w`` (sy, sx), centroid and major-axis angle)
    into two markers along its major axis.

    The cut is the weighted 2-means (Otsu) split of the pixels' positions along the axis; it is
    accepted when the weight profile along the axis dips at the cut to at most ``waist_ratio``
    of its value at the two part centres (two touching discs have a waist, one blurred disc
    does not) and the lighter part weighs at least ``min_mass_ratio`` of the heavier. Returns
    the two boolean half-plane masks, or None.
    """
    h, wd = w.shape
    u = ((np.arange(wd) - cx) * math.cos(angle))[None, :] \
        + ((np.arange(h) - cy) * math.sin(angle))[:, None]
    on = w > 0
    order = np.argsort(u[on], kind="stable")
    uu, ww = u[on][order], w[on][order].astype(np.float64)
    # between-class variance of every split of the sorted positions, from cumulative sums
    cw, cu = np.cumsum(ww)[:-1], np.cumsum(ww * uu)[:-1]
    total_w, total_u = cw[-1] + ww[-1], cu[-1] + ww[-1] * uu[-1]
    ok = (cw > 0) & (total_w - cw > 0)
    if not ok.any():
        return None
    ml = cu / np.where(ok, cw, 1.0)
    mr = (total_u - cu) / np.where(ok, total_w - cw, 1.0)
    between = np.where(ok, cw * (total_w - cw) * (ml - mr) ** 2, -1.0)
    i = int(np.argmax(between))
    wl, wr, ml, mr = float(cw[i]), float(total_w - cw[i]), float(ml[i]), float(mr[i])
    cut = 0.5 * (uu[i] + uu[i + 1])
    if min(wl, wr) < min_mass_ratio * max(wl, wr):
        return None
    # weight profile along the axis in 1-px bins, read at the cut and at the part centres
    start = math.floor(uu[0])
    bins = np.bincount((uu - start).astype(int), weights=ww).tolist()

    def at(x: float) -> float:
        i = int(x - start)
        near = bins[max(i - 1, 0) : i + 2]
        return sum(near) / max(len(near), 1)

    if at(cut) > waist_ratio * min(at(ml), at(mr)):
        return None
    return u < cut, u >= cut


def unmix_two_backgrounds_stack(
    patch: np.ndarray, ring_px: np.ndarray, ring: np.ndarray, m: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Coverage of the marker colour at each pixel of blob windows whose background is two
    surfaces (hand edge, occluder edge), for a stack of blobs at once.

    Each ring's samples are split in two at their blueness (against the ring mean), then each
    pixel is unmixed against the background colour that explains it better (smaller residual).
    Negative coverage is clipped: here the less blue background is not zero-mean noise.

    ``patch`` (n, sy, sx, 3) BGR windows; ``ring_px`` (n, P, 3) float64 colours of the
    background samples' windows and ``ring`` (n, P) bool which of them are ring pixels (at
    least one each); ``m``, ``b`` (n, 3) marker colours and ring means. Returns the coverage
    (n, sy, sx) float32; (n,) bool: False where a ring does not split into two parts of 3
    samples or more (there :func:`blueness` against ``b`` applies, the coverage is undefined);
    the two background colours (n, 2, 3); and (n, sy, sx) bool: the pixel took the first.
    """
    n, sy, sx, _ = patch.shape
    proj = ((ring_px - b[:, None, :]) @ (m - b)[:, :, None])[:, :, 0]
    low = ring & (proj < 0)
    high = ring & ~low
    parts = np.stack([low, high], 1).astype(np.float64)  # (n, 2, P)
    counts = parts.sum(2)  # (n, 2)
    ok = counts.min(1) >= 3
    bg = (parts @ ring_px) / np.maximum(counts, 1)[:, :, None]  # (n, 2, 3)
    d = m[:, None, :] - bg
    dd = (d * d).sum(2)  # (n, 2)
    g = d / np.maximum(dd, 100.0)[:, :, None]
    # a "background" this close to the marker cannot be unmixed from: infinite residual
    off = np.where(dd < 100.0, np.inf, 0.0) + (bg * bg).sum(2)  # (n, 2)
    gb = (bg * g).sum(2)
    px = patch.reshape(n, -1, 3).astype(np.float64)
    # per pixel p and background k: coverage a = (p - bg).g and squared residual
    # |p - bg|^2 - a^2 |d|^2; |p|^2 is common to both backgrounds and left out
    prod = np.concatenate([g, bg], 1) @ px.transpose(0, 2, 1)  # (n, 4, Q): p.g_k, p.bg_k
    a0 = prod[:, 0] - gb[:, :1]
    a1 = prod[:, 1] - gb[:, 1:]
    r0 = off[:, :1] - 2 * prod[:, 2] - a0 * a0 * dd[:, :1]
    r1 = off[:, 1:] - 2 * prod[:, 3] - a1 * a1 * dd[:, 1:]
    first = r0 <= r1
    best = np.where(first, a0, a1)
    return (np.maximum(best, 0).astype(np.float32).reshape(n, sy, sx), ok, bg,
            first.reshape(n, sy, sx))
