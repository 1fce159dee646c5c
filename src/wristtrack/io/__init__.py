"""Recording input and output: native folders, videos, ROS bags and live cameras.

``open_recording(source)`` picks the reader; every reader yields :class:`Frame` s one at a time.
"""

from wristtrack.io.recording import Frame, Recording, RecordingWriter, open_recording

__all__ = ["Frame", "Recording", "RecordingWriter", "open_recording"]
