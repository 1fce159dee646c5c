"""The marker detector's thresholds, in one place."""

from __future__ import annotations

from dataclasses import dataclass

from wristtrack.errors import ConfigError
from wristtrack.hand import MARKER_DIAMETER_M


@dataclass(frozen=True)
class DetectorConfig:
    """Thresholds of the marker detector. Colours are OpenCV 8-bit: HSV hue 0..179 (degrees / 2),
    saturation and value 0..255; YCrCb 0..255 each. Pixel sizes are full resolution.

    ``preset`` "paper" (:meth:`paper`) is the paper's detection as published, without our
    refinements (:mod:`wristtrack.detect.paper`)."""

    preset: str = "default"  # one of PRESETS
    learn_colours: bool = True  # learn_markers / adapt refine the marker and skin colours

    # --- skin region of interest (YCrCb, computed on a 1/skin_downsample image)
    skin_downsample: int = 4  # even
    skin_cr: tuple[float, float] = (133.0, 173.0)  # fixed box before adaptation (Chai & Ngan)
    skin_cb: tuple[float, float] = (77.0, 127.0)
    skin_y_min: int = 40  # darker pixels are not skin candidates: their chroma is noise
    skin_mahalanobis: float = 3.5  # adapted model: skin if CrCb Mahalanobis distance <= this
    skin_min_sigma: float = 2.0  # floor added to the fitted CrCb sigmas (levels)
    skin_adapt_frames: int = 5  # fit the subject's chroma over the first frames with skin; 0: off
    skin_min_samples: int = 200  # chroma samples needed for a fit
    skin_dilate_px: int = 12  # skin mask growth: closes marker holes, reaches edge markers
    skin_min_fraction: float = 0.004  # smallest skin component used, fraction of the image
    skin_max_fraction: float = 0.5  # larger "skin" components are background, not a hand
    skin_component_ratio: float = 0.3  # also keep components at least this x the largest
    skin_max_components: int = 3
    roi_margin_px: int = 16  # added around the skin bounding box
    track_roi: bool = True  # search first near the last frame's blobs, all the skin if short
    track_margin_px: int = 40  # around the last blobs' box: covers ~1.2 m/s at 0.5 m, 30 fps
    track_margin_ratio: float = 0.5  # or this fraction of the blobs' spread, if larger
    require_skin: bool = True  # ignore blobs whose centre is off the dilated skin

    # --- marker colour (HSV); the default reference before learn_markers is a Gaussian
    marker_hue: float = 110.0  # blue (220 degrees)
    marker_hue_sigma: float = 8.0
    marker_sat: float = 200.0
    marker_sat_sigma: float = 60.0
    min_saturation: int = 50  # greyer pixels never count as marker: their hue is noise
    min_value: int = 32  # nor darker ones (value gate in bins of 32)
    hist_bins: tuple[int, int] = (30, 16)  # (hue, saturation) bins
    backproject_threshold: float = 0.25  # marker pixel: back-projection >= this x reference peak
    min_similarity: float = 0.6  # Bhattacharyya coefficient blob histogram vs reference

    # --- size and shape, relative to the expected marker diameter where it is known
    marker_diameter_m: float = MARKER_DIAMETER_M
    min_area_px: int = 6
    max_blob_px: int = 80  # blobs with a longer box side are not markers (a 12 mm disc at 8 cm)
    min_size_ratio: float = 0.45  # major axis / expected diameter below: not a whole marker
    merge_ratio: float = 1.2  # above: too long for one marker (merged pair, motion blur)
    psf_sigma_px: float = 0.7  # optical blur: a disc of diameter D measures sqrt(D^2 + 16 s^2)
    max_size_ratio: float = 3.2  # above: not marker(s)
    min_axis_ratio: float = 0.2  # minor / major below: a line, not a disc (~78 deg tilt)
    min_fill: float = 0.45  # weighted area / moment-ellipse area below: irregular shape. A
    # sharp disc is ~0.93; under every realism effect at once (blur, JPEG, Bayer, shading)
    # blobs measure 0.69 at the median, 0.48 at the 0.1 % quantile (both hands, 3 seeds; 0.55
    # dropped 1-3 % of a left hand's markers at 45 deg flexion)
    max_skew: float = 0.18  # skewness above: clipped (lopsided) blob; ~8 % of a disc hidden
    waist_ratio: float = 0.85  # split a long blob where its profile dips to this fraction
    split_min_mass_ratio: float = 0.35
    blur_margin: int = 1  # half-res pixels beyond a blob's box that may still carry its colour
    mixed_background: float = 0.15  # background colour spread / marker contrast above which
    # the background is unmixed as two surfaces (blob on the hand's edge, at an occluder)
    highlight_excess: float = 40.0  # grey levels above the marker-skin line: a specular spot
    min_contrast: float = 10.0  # marker vs background colour distance (levels) below: no blob
    max_candidates: int = 24  # per frame, largest first: bounds the per-blob work
    depth_size_tolerance: float = 0.2  # blob's own depth used for its expected size if within
    # this (relative) of the frame's median, else the median (an edge blob may see the table)

    # --- depth
    depth_trim: tuple[float, float] = (0.2, 0.8)  # quantiles kept for the trimmed mean

    # --- learn_markers
    learn_radius_px: int = 18  # half-size of the patch examined around each labelled marker

    @classmethod
    def paper(cls) -> DetectorConfig:
        """The paper's section III-A as published: a fixed skin-colour region of interest (no
        adaptation to the subject, no tracked window, no per-blob skin gate), marker pixels by
        back-projection of the fixed reference histogram (no learned colour), connected
        components at full resolution, each kept when its Bhattacharyya coefficient with the
        reference is high enough; its centre the centroid of its pixels (see
        :mod:`wristtrack.detect.paper` for what is left out)."""
        return cls(preset="paper", learn_colours=False, skin_adapt_frames=0, track_roi=False,
                   require_skin=False)


PRESETS = {"default": DetectorConfig, "paper": DetectorConfig.paper}


def detector_config(name: str) -> DetectorConfig:
    """The detector configuration of preset ``name`` (one of :data:`PRESETS`)."""
    if name not in PRESETS:
        raise ConfigError(f"unknown detector {name!r}: choose from {', '.join(PRESETS)}")
    return PRESETS[name]()
