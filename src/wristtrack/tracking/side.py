"""Which hand: label the blobs with the right-hand template and with its mirror image.

Without hand.json the markers are labelled with a template (``HandLayout.default()``, a right
hand) before the subject's layout is measured from depth. A left hand seen from the back is the
mirror image of a right one, so the right template's triangle-orientation tests reject its true
labelling and can accept a mirrored one instead (WRIST<->CMC1, MCP2<->MCP5): the hand was then
tracked as a right hand with wrong labels. DESIGN.md section 2: the side must be found from the
image, never assumed. So both templates are tried at every initialisation; the one whose best
labelling fits clearly better wins, and when neither fits clearly better than the other the
initialisation is refused (the next frame tries again) rather than guessed.
"""

from __future__ import annotations

import numpy as np

from wristtrack.camera import Camera
from wristtrack.detect.detections import Detections
from wristtrack.errors import InitialisationError
from wristtrack.hand import HandLayout
from wristtrack.tracking.labelling import AMBIGUITY_RATIO, MAX_RMS_PX, label_and_fit
from wristtrack.tracking.pose_fit import PoseFit

# The wrong side must cost at least this much more (chi-square) than the right one, besides
# AMBIGUITY_RATIO times as much: a difference noise alone reaches with probability ~0.3 % (one
# degree of freedom), so two near-zero costs of a well-fitting template are not told apart.
MIN_COST_GAP = 9.0


def label_either_side(
    detections: Detections,
    camera: Camera,
    *,
    pixel_sigma: float = 0.7,
    max_rms_px: float = MAX_RMS_PX,
    ratio: float = AMBIGUITY_RATIO,
) -> tuple[np.ndarray, str, PoseFit]:
    """(labels (M,), side "right"/"left", the fit) of the template side that fits clearly best.

    Raises InitialisationError when neither template labels the blobs (the reasons of both),
    or when both do and the worse costs less than ``ratio`` times the better or less than
    MIN_COST_GAP more: a side cannot be told, so none is claimed.
    """
    right = HandLayout.default()
    fits: dict[str, tuple[np.ndarray, PoseFit]] = {}
    errors: dict[str, str] = {}
    for side, template in (("right", right), ("left", right.mirrored())):
        try:
            fits[side] = label_and_fit(
                detections.uv, detections.depth, camera, template,
                pixel_sigma=pixel_sigma, template=True, max_rms_px=max_rms_px,
            )  # fmt: skip
        except InitialisationError as e:
            errors[side] = str(e)
    if not fits:
        reason = errors["right"]
        if errors["left"] != reason:
            reason = f"right hand: {reason}; left hand: {errors['left']}"
        raise InitialisationError(reason)
    ranked = sorted(fits.items(), key=lambda kv: kv[1][1].cost)
    side, (labels, fit) = ranked[0]
    if len(ranked) == 2:
        other = ranked[1][1][1]
        if other.cost < ratio * fit.cost or other.cost - fit.cost < MIN_COST_GAP:
            raise InitialisationError(
                f"cannot tell a left from a right hand: both fit the markers (chi-square "
                f"{fit.cost:.1f} as a {side} hand, {other.cost:.1f} as a {ranked[1][0]} one); "
                "show the back of the hand squarely to the camera, or give a hand.json (--hand)"
            )
    return labels, side, fit
