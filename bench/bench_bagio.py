"""Bag input and output throughput: write a camera bag, read its frames back, summarise it.

Writes N frames of WxH as rgb8 Image, JPEG and PNG CompressedImage (with CameraInfo and odometry)
into an MCAP bag and a sqlite3 bag in a temporary folder, then times ``read_frames`` per topic and
``summarize`` on each. Usage: .venv/bin/python bench/bench_bagio.py [--frames 60] [--size 1280x720]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from stockpile_ros.bagio.reader import read_frames
from stockpile_ros.bagio.summary import summarize
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.camera import CameraModel
from stockpile_ros.ros import messages as m
from stockpile_ros.ros.typestore import typestore


def make_items(frames: int, width: int, height: int) -> list[tuple[str, object, int]]:
    f = m.RosbagsFactory(typestore())
    cam = CameraModel.from_fov(width, height, 70.0, frame_id='cam')
    yy, xx = np.mgrid[0:height, 0:width]
    items: list[tuple[str, object, int]] = []
    for i in range(frames):
        t = 10**9 + i * 10**8
        img = np.stack([(xx + 3 * i) % 256, (yy + i) % 256, (xx ^ yy) % 256], axis=2).astype(
            np.uint8
        )
        items.append(('/cam/image_raw', m.image(f, img, t, 'cam'), t))
        items.append(('/cam/image_raw/compressed', m.compressed_image(f, img, t, 'cam'), t))
        items.append(('/png/image_raw/compressed', m.compressed_image(f, img, t, 'cam', 'png'), t))
        items.append(('/cam/camera_info', m.camera_info(f, cam, t), t))
        items.append(('/odom', m.odometry(f, t, [i * 0.1, 0, 0], [0, 0, 0, 1]), t))
    return items


def write_sqlite(path: Path, items: list[tuple[str, object, int]]) -> None:
    store = typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conns: dict[str, object] = {}
        for topic, msg, stamp in items:
            msgtype = msg.__msgtype__  # type: ignore[attr-defined]
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], stamp, store.serialize_cdr(msg, msgtype))  # type: ignore[arg-type]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--frames', type=int, default=60)
    parser.add_argument('--size', default='1280x720')
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split('x'))
    items = make_items(args.frames, width, height)
    print(f'{args.frames} frames of {width}x{height}')
    with tempfile.TemporaryDirectory() as tmp:
        bags = {'mcap': Path(tmp, 'mcap'), 'sqlite3': Path(tmp, 'sqlite3')}
        t0 = time.perf_counter()
        with BagWriter(bags['mcap']) as bag:
            for topic, msg, stamp in items:
                bag.write(topic, msg, stamp)
        t1 = time.perf_counter()
        write_sqlite(bags['sqlite3'], items)
        t2 = time.perf_counter()
        print(f'write mcap {t1 - t0:.2f} s, sqlite3 {t2 - t1:.2f} s ({len(items)} messages each)')
        for name, bag_path in bags.items():
            for topic in (
                '/cam/image_raw',
                '/cam/image_raw/compressed',
                '/png/image_raw/compressed',
            ):
                t = time.perf_counter()
                frames = list(read_frames(bag_path, topic))
                dt = time.perf_counter() - t
                assert len(frames) == args.frames and all(fr.camera for fr in frames)
                print(f'{name:8s} read_frames {topic:28s} {dt:6.2f} s  {len(frames) / dt:7.1f} fps')
            t = time.perf_counter()
            summarize(bag_path)
            dt = time.perf_counter() - t
            print(f'{name:8s} summarize (decodes all 3 image topics)  {dt:6.2f} s')


if __name__ == '__main__':
    main()
