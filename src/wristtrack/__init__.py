"""wristtrack: 6-DoF wrist pose from one RGB-D camera and six blue markers on the hand."""

__version__ = "0.1.0"
