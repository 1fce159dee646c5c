"""Marker trajectories in and out: the in-memory forms, and one module per file format (C3D,
TRC, ...). :mod:`.formats` writes a :class:`.trajectories.MarkerTrajectories` by format name."""
