"""Recording input and output: native folders, videos, ROS bags, live cameras; run files.

Kept import-free so that ``import wristtrack.io.poses`` does not pull in OpenCV and every
reader. Where things are:

- ``io.open.open_recording(source)`` picks the reader for any kind of recording;
- ``io.base``: :class:`Frame`, :class:`Recording` (the interface every source implements);
- ``io.folder``: the native recording folder (``FolderRecording``, ``RecordingWriter``);
- ``io.video``, ``io.live``, ``io.rosbag`` (+ ``io.ros_messages``): the other sources;
- ``io.poses``, ``io.states``, ``io.run_folder``: the files of a tracking run;
- ``io.markers``: marker trajectories and their formats (C3D, TRC);
- ``io.atomic``: the one way files are replaced atomically.
"""
