"""cli.options: the tracker options every tracking command shares."""

from __future__ import annotations

import argparse

from wristtrack.cli.options import add_tracker_options, tracker_config
from wristtrack.tracking.surface import SurfaceSettings


def parse(*argv: str):
    parser = argparse.ArgumentParser()
    add_tracker_options(parser)
    return tracker_config(parser.parse_args(list(argv)))


def test_the_skin_between_the_markers_is_used_unless_switched_off():
    assert parse().surface == SurfaceSettings()
    off = parse("--no-skin-depth")
    assert off.surface is None and off.use_depth
    assert parse("--no-depth").use_depth is False


def test_the_papers_method_never_reads_the_skin():
    assert parse("--model", "paper").surface is None


def test_the_noise_is_learned_unless_fixed():
    learned = parse()
    assert learned.adapt_slide and learned.learns_pixel_noise
    fixed = parse("--fixed-noise")
    assert not fixed.adapt_slide and not fixed.learns_pixel_noise
    assert not parse("--model", "paper").learns_pixel_noise  # the paper's 0.7 px throughout
    assert not parse("--association", "jpda").learns_pixel_noise
