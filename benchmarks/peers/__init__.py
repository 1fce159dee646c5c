"""Peer methods the benchmarks compare wristtrack with (need the ``bench`` extra for Stone Soup).

Each is a per-frame tracker with ``step(detections) -> tracker.FrameResult``, so the benchmark
scores it with the same code as wristtrack's own tracker.
"""
