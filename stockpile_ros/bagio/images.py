"""Decode ``sensor_msgs/Image`` and ``sensor_msgs/CompressedImage`` into numpy arrays.

Works on any object with the message's field names (rosbags dataclasses, rclpy messages), so the bag
reader and the live nodes share it. Output conventions:

- colour sources (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, Bayer, YUV 4:2:2, JPEG, PNG) give an
  HxWx3 ``uint8`` array in RGB order (alpha dropped);
- ``mono8`` / ``8UC1`` give HxW ``uint8``;
- ``mono16`` / ``16UC1`` give HxW ``uint16`` in native byte order.

Every malformed message raises :class:`ImageError` saying what is wrong.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from ..errors import StockpileError

__all__ = [
    'RAW_ENCODINGS',
    'ImageError',
    'decode_compressed',
    'decode_image',
    'decode_raw',
    'describe_encoding',
]


class ImageError(StockpileError, ValueError):
    """An image message that cannot be decoded; the text says why."""


# encoding -> (channels, bytes per channel). Bayer and YUV 4:2:2 are stored as one 8-bit plane of
# width x height (Bayer) or two bytes per pixel (YUV).
_LAYOUT: dict[str, tuple[int, int]] = {
    'rgb8': (3, 1),
    'bgr8': (3, 1),
    'rgba8': (4, 1),
    'bgra8': (4, 1),
    'mono8': (1, 1),
    '8uc1': (1, 1),
    'mono16': (1, 2),
    '16uc1': (1, 2),
    'bayer_rggb8': (1, 1),
    'bayer_bggr8': (1, 1),
    'bayer_gbrg8': (1, 1),
    'bayer_grbg8': (1, 1),
    'uyvy': (2, 1),
    'yuv422': (2, 1),
    'yuyv': (2, 1),
    'yuv422_yuy2': (2, 1),
}

# OpenCV names a Bayer pattern after the second row's second and third pixels, so the ROS pattern
# read from the top-left corner maps to the "opposite" name (checked by the tests on a mosaic).
_BAYER = {
    'bayer_rggb8': cv2.COLOR_BayerBG2RGB,
    'bayer_bggr8': cv2.COLOR_BayerRG2RGB,
    'bayer_gbrg8': cv2.COLOR_BayerGR2RGB,
    'bayer_grbg8': cv2.COLOR_BayerGB2RGB,
}

_YUV = {
    'uyvy': cv2.COLOR_YUV2RGB_UYVY,
    'yuv422': cv2.COLOR_YUV2RGB_UYVY,
    'yuyv': cv2.COLOR_YUV2RGB_YUYV,
    'yuv422_yuy2': cv2.COLOR_YUV2RGB_YUYV,
}

RAW_ENCODINGS: tuple[str, ...] = tuple(_LAYOUT)
"""The ``sensor_msgs/Image`` encodings :func:`decode_raw` understands (lower case)."""

_JPEG_MAGIC = b'\xff\xd8\xff'
_PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
# compressed_depth_image_transport puts a 12-byte ConfigHeader (format, depth quantisation) before
# the PNG stream.
_DEPTH_HEADER_BYTES = 12


def _as_bytes(data: Any) -> npt.NDArray[np.uint8]:
    """View a ``uint8[]`` field (numpy array, bytes, array.array, list) as a flat uint8 array."""
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    if isinstance(data, (bytes, bytearray, memoryview)):
        return np.frombuffer(data, dtype=np.uint8)
    try:
        return np.frombuffer(memoryview(data), dtype=np.uint8)
    except TypeError:
        return np.asarray(data, dtype=np.uint8).reshape(-1)


def _u8(img: Any) -> npt.NDArray[np.uint8]:
    return np.asarray(img, dtype=np.uint8)


def describe_encoding(msg: Any) -> str:
    """Return the encoding of an Image or the format of a CompressedImage, as stored."""
    if hasattr(msg, 'format'):
        return str(msg.format)
    return str(msg.encoding)


def decode_raw(msg: Any) -> npt.NDArray[Any]:
    """Decode a ``sensor_msgs/Image``.

    Honours ``step`` (row padding) and ``is_bigendian`` (16-bit encodings).

    Args:
        msg: An object with the fields of ``sensor_msgs/Image``.

    Returns:
        HxWx3 uint8 RGB for colour encodings, HxW uint8 for mono8, HxW uint16 for mono16/16UC1.

    Raises:
        ImageError: Unknown encoding, empty or inconsistent size, or data shorter than the
            header says.

    """
    encoding = str(msg.encoding).strip()
    key = encoding.lower()
    if key not in _LAYOUT:
        known = ', '.join(RAW_ENCODINGS)
        raise ImageError(f'unsupported image encoding {encoding!r} (supported: {known})')
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise ImageError(f'empty image: {width}x{height} {encoding}')
    channels, depth = _LAYOUT[key]
    row_bytes = width * channels * depth
    if step < row_bytes:
        raise ImageError(
            f'step {step} is smaller than one row of {width} {encoding} pixels ({row_bytes} bytes)'
        )
    if key in _YUV and width % 2:
        raise ImageError(f'{encoding} needs an even width, got {width}')
    data = _as_bytes(msg.data)
    needed = height * step
    # The last row's padding is sometimes left out; everything the pixels need must be there.
    if data.size < needed - (step - row_bytes):
        raise ImageError(
            f'data holds {data.size} bytes but {width}x{height} {encoding} with step {step} '
            f'needs {needed}'
        )
    if data.size < needed:
        data = np.concatenate([data, np.zeros(needed - data.size, dtype=np.uint8)])
    rows = data[:needed].reshape(height, step)[:, :row_bytes]
    if depth == 2:
        order = '>' if bool(msg.is_bigendian) else '<'
        plane = np.ascontiguousarray(rows).view(f'{order}u2').astype(np.uint16)
        return plane.reshape(height, width)
    pixels: npt.NDArray[np.uint8] = np.ascontiguousarray(rows).reshape(height, width, channels)
    if key in ('mono8', '8uc1'):
        return np.array(pixels[:, :, 0])
    if key == 'rgb8':
        return np.array(pixels)
    if key == 'rgba8':
        return np.ascontiguousarray(pixels[:, :, :3])
    if key in ('bgr8', 'bgra8'):
        return np.ascontiguousarray(pixels[:, :, 2::-1])
    if key in _BAYER:
        return _u8(cv2.cvtColor(pixels[:, :, 0], _BAYER[key]))
    return _u8(cv2.cvtColor(pixels, _YUV[key]))


def _container(data: npt.NDArray[np.uint8], fmt: str) -> tuple[str, npt.NDArray[np.uint8]]:
    """Find the JPEG or PNG stream in ``data``; returns its kind and bytes."""
    head = data[:16].tobytes()
    if 'compresseddepth' in fmt.lower() and data[_DEPTH_HEADER_BYTES:].tobytes().startswith(
        _PNG_MAGIC
    ):
        return 'png', data[_DEPTH_HEADER_BYTES:]
    if head.startswith(_JPEG_MAGIC):
        return 'jpeg', data
    if head.startswith(_PNG_MAGIC):
        return 'png', data
    lowered = fmt.lower()
    if not any(name in lowered for name in ('jpeg', 'jpg', 'png')):
        raise ImageError(f'unsupported compressed format {fmt!r} (supported: jpeg, png)')
    raise ImageError(
        f'format {fmt!r} but the data is neither JPEG nor PNG (starts with {head[:8].hex(" ")})'
    )


def decode_compressed(msg: Any) -> npt.NDArray[Any]:
    """Decode a ``sensor_msgs/CompressedImage`` holding JPEG or PNG.

    The container is recognised by its signature; ``format`` may be ``"jpeg"``, ``"png"`` or the
    image_transport form ``"rgb8; jpeg compressed bgr8"`` (``compressedDepth`` PNGs too).

    Args:
        msg: An object with ``format`` and ``data``.

    Returns:
        HxWx3 uint8 RGB for colour images, HxW uint8 or uint16 for grey ones.

    Raises:
        ImageError: Empty, truncated or undecodable data, or a format other than JPEG/PNG.

    """
    fmt = str(msg.format).strip()
    data = _as_bytes(msg.data)
    if data.size == 0:
        raise ImageError(f'compressed image ({fmt!r}) holds no data')
    kind, stream = _container(data, fmt)
    # libjpeg fills a truncated scan with grey and only warns; catch truncation before decoding.
    if kind == 'jpeg':
        tail = np.trim_zeros(stream, 'b')[-2:].tobytes()
        if tail != b'\xff\xd9':
            raise ImageError(
                f'truncated JPEG: {stream.size} bytes without an end-of-image marker '
                f'(format {fmt!r})'
            )
    elif b'IEND' not in stream[-16:].tobytes():
        raise ImageError(
            f'truncated PNG: {stream.size} bytes without an IEND chunk (format {fmt!r})'
        )
    try:
        img = cv2.imdecode(stream, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageError(f'OpenCV cannot decode the {kind.upper()} data: {exc}') from None
    if img is None or img.size == 0:
        raise ImageError(f'OpenCV cannot decode the {stream.size}-byte {kind.upper()} data')
    if img.ndim == 3 and img.dtype == np.uint16:
        img = (img // 257).astype(np.uint8)
    if img.ndim == 2:
        return np.asarray(img)
    if img.shape[2] == 4:
        return _u8(cv2.cvtColor(img, cv2.COLOR_BGRA2RGB))
    return _u8(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))


def decode_image(msg: Any) -> npt.NDArray[Any]:
    """Decode either image message: a CompressedImage (has ``format``) or an Image.

    Raises:
        ImageError: The message cannot be decoded; the text says why.

    """
    if hasattr(msg, 'format'):
        return decode_compressed(msg)
    return decode_raw(msg)
