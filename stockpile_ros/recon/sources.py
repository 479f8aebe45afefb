"""Frames and odometry from what a person hands over: a ROS 2 bag, a folder of photos, a video file.

Bags carry CameraInfo and odometry; odometry is given for ``base_link`` and turned into camera
positions with the transforms from ``/tf_static`` and ``/tf`` (a camera on a moving mast included).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from PIL import ImageOps

from ..camera import Frame
from ..errors import StockpileError
from ..ros.images import DEFAULT_MAX_PIXELS, ImageError, check_pixels, image_size
from .exif import HEIF_SUFFIXES, open_photo

__all__ = ['IMAGE_SUFFIXES', 'VIDEO_SUFFIXES', 'iter_frames', 'photo_files', 'source_kind']

IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', *HEIF_SUFFIXES)
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


def photo_files(folder: Path) -> list[Path]:
    """Return the photos of a folder, sorted by name (a frame's ``index`` is its position here)."""
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)


def _heif(path: Path, max_pixels: int) -> npt.NDArray[np.uint8]:
    """Decode a HEIC/HEIF photo to RGB (its rotation applied), its size checked first."""
    with open_photo(path) as image:
        try:
            check_pixels(image.width, image.height, max_pixels, path.name)
        except ImageError as exc:
            raise StockpileError(f'{path}: {exc}') from None
        return np.asarray(ImageOps.exif_transpose(image).convert('RGB'), dtype=np.uint8)


def _photos(folder: Path, max_pixels: int) -> Iterator[Frame]:
    for index, path in enumerate(photo_files(folder)):
        if path.suffix.lower() in HEIF_SUFFIXES:
            rgb = _heif(path, max_pixels)
            yield Frame(index * 1_000_000_000, rgb, path.name, None, str(folder), index)
            continue
        data = path.read_bytes()
        try:
            _, width, height = image_size(data)
        except ImageError:
            continue  # not an image OpenCV could read either: skipped, as unreadable files are
        # The decoder allocates what the header says, whatever the file's size: check it first.
        try:
            check_pixels(width, height, max_pixels, path.name)
        except ImageError as exc:
            raise StockpileError(f'{path}: {exc}') from None
        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
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


def _video(path: Path, max_pixels: int) -> Iterator[Frame]:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise StockpileError(f'{path}: OpenCV cannot open this video')
    index = 0
    try:
        # The container states the stream's size; check it before the first frame is decoded.
        width = round(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = round(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        try:
            check_pixels(width, height, max_pixels, f'video frame of {path.name}')
        except ImageError as exc:
            raise StockpileError(f'{path}: {exc}') from None
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


def iter_frames(
    source: Path, topic: str | None = None, *, max_pixels: int = DEFAULT_MAX_PIXELS
) -> Iterator[Frame]:
    """Frames of a bag (one image topic), a folder of photos (sorted by name) or a video.

    Args:
        source: Bag, photo folder or video file.
        topic: The bag's image topic (None: the one with most messages).
        max_pixels: Largest ``width * height`` decoded, read from each header before decoding.
            A bag's larger images are skipped as bad messages; a larger photo or video ends the
            run.

    Raises:
        StockpileError: (on iteration) a photo or video over the limit, or an unreadable source.

    """
    kind = source_kind(source)
    if kind == 'bag':
        from ..bagio.reader import read_frames

        yield from read_frames(source, topic, max_pixels=max_pixels)
    elif kind == 'photos':
        yield from _photos(source, max_pixels)
    else:
        yield from _video(source, max_pixels)
