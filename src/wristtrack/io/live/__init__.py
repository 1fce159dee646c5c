"""Live sources for `track --live`: an OpenCV camera, RealSense, OpenNI2, a replayed folder;
and the `--record` writer."""
