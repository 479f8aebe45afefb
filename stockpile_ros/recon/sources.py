"""Frames and odometry from what a person hands over: a ROS 2 bag, a folder of photos, a video file.

Bags carry CameraInfo and odometry; odometry is given for ``base_link`` and turned into camera
positions with the transforms from ``/tf_static`` and ``/tf`` (a camera on a moving mast included).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2

from ..camera import Frame
from ..errors import StockpileError

__all__ = ['IMAGE_SUFFIXES', 'VIDEO_SUFFIXES', 'iter_frames', 'source_kind']

IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff')
VIDEO_SUFFIXES = ('.mp4', '.mov', '.avi', '.mkv', '.webm', '.m4v')


def source_kind(source: Path) -> str:
    """``"bag"``, ``"photos"`` or ``"video"``.

    Raises:
        StockpileError: The path is none of them.

    """
    if source.is_dir():
        if (
            (source / 'metadata.yaml').exists()
            or any(source.glob('*.mcap'))
            or any(source.glob('*.db3'))
        ):
            return 'bag'
        if any(p.suffix.lower() in IMAGE_SUFFIXES for p in source.iterdir()):
            return 'photos'
    elif source.suffix.lower() in ('.mcap', '.db3'):
        return 'bag'
    elif source.suffix.lower() in VIDEO_SUFFIXES and source.exists():
        return 'video'
    raise StockpileError(
        f'{source}: not a ROS 2 bag, a folder of photos or a video file '
        f'({", ".join(VIDEO_SUFFIXES)})'
    )


def _photos(folder: Path) -> Iterator[Frame]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    for index, path in enumerate(files):
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            continue
        # Photos carry no stamps worth trusting; their order is their time.
        yield Frame(
            index * 1_000_000_000,
            cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
            path.name,
            None,
            str(folder),
            index,
        )


def _video(path: Path) -> Iterator[Frame]:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise StockpileError(f'{path}: OpenCV cannot open this video')
    index = 0
    try:
        while True:
            ok, bgr = capture.read()
            if not ok:
                break
            stamp = round(capture.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
            yield Frame(
                stamp, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), path.name, None, str(path), index
            )
            index += 1
    finally:
        capture.release()


def iter_frames(source: Path, topic: str | None = None) -> Iterator[Frame]:
    """Frames of a bag (one image topic), a folder of photos (sorted by name) or a video."""
    kind = source_kind(source)
    if kind == 'bag':
        from ..bagio.reader import read_frames

        yield from read_frames(source, topic)
    elif kind == 'photos':
        yield from _photos(source)
    else:
        yield from _video(source)
