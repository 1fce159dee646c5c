"""How realsense_sdk256.bag was written: ``python make_realsense_bag.py OUT.bag`` with
pyrealsense2 2.56 (the last SDK whose recorder writes ROS 1 .bag, the layout RealSense Viewer
recordings have; later ones write .db3).

A software device with a depth (Z16, 0.1 mm units) and a colour (BGR8) sensor, 64x48,
Brown-Conrady intrinsics, identity extrinsics, recorded by the SDK's own recorder: frame i has
colour pixel (r, c) = (i, r + 10, c) in BGR order and depth 1000 + 10 i + r + c, timestamp
i / 30 s, injected at 30 fps. (The recorder misses the first frame.)
"""

import sys
import time

import numpy as np
import pyrealsense2 as rs

W, H, N = 64, 48, 8
FX, FY, CX, CY = 50.5, 51.25, 31.5, 23.75
DIST = [0.1, -0.2, 0.001, 0.002, 0.01]
DEPTH_UNITS = 0.0001


def main(path: str) -> None:
    dev = rs.software_device()
    depth_sensor, color_sensor = dev.add_sensor("Depth"), dev.add_sensor("Color")
    intr = rs.intrinsics()
    intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = W, H, FX, FY, CX, CY
    intr.model, intr.coeffs = rs.distortion.brown_conrady, DIST
    profiles = []
    for sensor, kind, fmt, bpp, uid in ((depth_sensor, rs.stream.depth, rs.format.z16, 2, 0),
                                        (color_sensor, rs.stream.color, rs.format.bgr8, 3, 1)):
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height = kind, 0, uid, W, H
        vs.fps, vs.bpp, vs.fmt, vs.intrinsics = 30, bpp, fmt, intr
        profiles.append(sensor.add_video_stream(vs).as_video_stream_profile())
    depth_profile, color_profile = profiles
    extrinsics = rs.extrinsics()
    extrinsics.rotation, extrinsics.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    depth_profile.register_extrinsics_to(color_profile, extrinsics)
    depth_sensor.add_read_only_option(rs.option.depth_units, DEPTH_UNITS)
    dev.create_matcher(rs.matchers.dlr_c)
    dev.register_info(rs.camera_info.name, "wristtrack test software device")
    recorder = rs.recorder(path, dev)
    depth_sensor.open(depth_profile)
    color_sensor.open(color_profile)
    depth_sensor.start(lambda f: None)
    color_sensor.start(lambda f: None)
    r, c = np.mgrid[0:H, 0:W]
    start, keep = time.perf_counter(), []
    for i in range(N):
        time.sleep(max(start + i / 30 - time.perf_counter(), 0.0))
        depth = (1000 + 10 * i + r + c).astype(np.uint16)
        color = np.stack([np.full((H, W), i), r + 10, c], -1).astype(np.uint8)
        for sensor, profile, image, bpp in ((depth_sensor, depth_profile, depth, 2),
                                            (color_sensor, color_profile, color, 3)):
            frame = rs.software_video_frame()
            frame.pixels = np.ascontiguousarray(image)
            keep.append(frame.pixels)  # the SDK reads the pixels after this call returns
            frame.bpp, frame.stride, frame.timestamp = bpp, W * bpp, i * 1000 / 30
            frame.frame_number, frame.profile = i, profile
            frame.domain = rs.timestamp_domain.hardware_clock
            if bpp == 2:
                frame.depth_units = DEPTH_UNITS
            sensor.on_video_frame(frame)
    time.sleep(0.1)
    for sensor in (depth_sensor, color_sensor):
        sensor.stop()
        sensor.close()
    del recorder


if __name__ == "__main__":
    main(sys.argv[1])
