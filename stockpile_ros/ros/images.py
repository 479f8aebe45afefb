"""Decode ``sensor_msgs/Image`` and ``sensor_msgs/CompressedImage`` into numpy arrays.

Works on any object with the message's field names (rosbags dataclasses, rclpy messages), so the bag
reader and the live nodes share it. Output conventions:

- colour sources (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, Bayer, YUV 4:2:2, JPEG, PNG) give an
  HxWx3 ``uint8`` array in RGB order (alpha dropped);
- ``mono8`` / ``8UC1`` give HxW ``uint8``;
- ``mono16`` / ``16UC1`` give HxW ``uint16`` in native byte order.

Every malformed message raises :class:`ImageError` saying what is wrong. Nothing is allocated for
the pixels before the size is known to be consistent and within a pixel limit: a raw Image's
``step``, ``height``, ``width`` and data length must agree, and a compressed image's dimensions are
read from its PNG or JPEG header before the decoder runs (the decoder allocates what the header
says, whatever the size of the compressed data).
"""

from __future__ import annotations

from typing import Any, Literal

import cv2
import numpy as np
import numpy.typing as npt

from ..errors import StockpileError

__all__ = [
    'DEFAULT_MAX_PIXELS',
    'RAW_ENCODINGS',
    'ImageError',
    'check_pixels',
    'decode_compressed',
    'decode_image',
    'decode_raw',
    'describe_encoding',
    'image_size',
]

DEFAULT_MAX_PIXELS = 50_000_000
"""Largest ``width * height`` decoded by default: twice a 24-megapixel camera's frame, far below
what a few header bytes can otherwise make a decoder allocate (30000x30000 RGB is 2.7 GB)."""


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
# A JPEG's frame header follows its APPn segments (EXIF, ICC profile, XMP): each is at most 64 KiB,
# so a megabyte reaches it in any camera's file without copying a large stream.
_HEADER_BYTES = 1 << 20


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


def check_pixels(width: int, height: int, max_pixels: int, what: str) -> None:
    """Refuse an image of more than ``max_pixels`` pixels (or none), before anything is allocated.

    Args:
        width: Width the header states [px].
        height: Height the header states [px].
        max_pixels: Largest ``width * height`` accepted.
        what: The image, in words, for the message (e.g. ``"PNG"`` or a file name).

    Raises:
        ImageError: Empty, or larger than the limit.

    """
    if width <= 0 or height <= 0:
        raise ImageError(f'empty image: {width}x{height} {what}')
    if width * height > max_pixels:
        raise ImageError(
            f'{what} is {width}x{height} = {width * height / 1e6:.1f} megapixels, over the limit '
            f'of {max_pixels / 1e6:g} megapixels per image'
        )


def decode_raw(msg: Any, max_pixels: int = DEFAULT_MAX_PIXELS) -> npt.NDArray[Any]:
    """Decode a ``sensor_msgs/Image``.

    Honours ``step`` (row padding) and ``is_bigendian`` (16-bit encodings). The data must hold
    ``height * step`` bytes, or that less the last row's padding (some drivers leave it out);
    anything else is refused, so that a header can never make the decoder invent pixels.

    Args:
        msg: An object with the fields of ``sensor_msgs/Image``.
        max_pixels: Largest ``width * height`` decoded.

    Returns:
        HxWx3 uint8 RGB for colour encodings, HxW uint8 for mono8, HxW uint16 for mono16/16UC1.

    Raises:
        ImageError: Unknown encoding, empty, over the pixel limit, or ``step``, size and data length
            that disagree.

    """
    encoding = str(msg.encoding).strip()
    key = encoding.lower()
    if key not in _LAYOUT:
        known = ', '.join(RAW_ENCODINGS)
        raise ImageError(f'unsupported image encoding {encoding!r} (supported: {known})')
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    check_pixels(width, height, max_pixels, encoding)
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
    shortest = needed - (step - row_bytes)
    if not shortest <= data.size <= needed:
        expected = f'{needed}' if shortest == needed else f'{shortest} to {needed}'
        raise ImageError(
            f'data holds {data.size} bytes but {width}x{height} {encoding} with step {step} '
            f'needs {expected}'
        )
    if step > data.size:
        # Only a single row can omit its padding and still hold its pixels; a step past the end
        # of the data is no row pitch of it.
        raise ImageError(
            f'step {step} is larger than the whole data ({data.size} bytes) of a {width}x{height} '
            f'{encoding} image'
        )
    # A strided view reads the rows in place: nothing beyond the pixels themselves is allocated.
    rows = np.lib.stride_tricks.as_strided(
        data, shape=(height, row_bytes), strides=(step, 1), writeable=False
    )
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


# Start-of-frame markers (baseline, extended, progressive, lossless, arithmetic): they carry the
# frame's size. C4 (DHT), C8 (reserved) and CC (DAC) are not frames.
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# Standalone markers have no length field: TEM and the restart markers.
_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})


def _jpeg_size(buf: bytes) -> tuple[int, int]:
    """Width and height from the first start-of-frame segment of a JPEG stream."""
    pos = 2  # after SOI
    while True:
        if pos >= len(buf) or buf[pos] != 0xFF:
            raise ImageError(f'JPEG header: no marker at byte {pos} before the frame header')
        while pos < len(buf) and buf[pos] == 0xFF:  # fill bytes may precede a marker
            pos += 1
        if pos + 3 > len(buf):
            raise ImageError(f'truncated JPEG header: {len(buf)} bytes end before the frame header')
        marker = buf[pos]
        pos += 1
        if marker in _JPEG_STANDALONE:
            continue
        if marker in (0xD8, 0xD9, 0xDA):
            raise ImageError(f'JPEG header: marker FF{marker:02X} before any frame header')
        length = int.from_bytes(buf[pos : pos + 2], 'big')
        if marker in _JPEG_SOF:
            if pos + 7 > len(buf) or length < 8:
                raise ImageError('truncated JPEG frame header')
            height = int.from_bytes(buf[pos + 3 : pos + 5], 'big')
            width = int.from_bytes(buf[pos + 5 : pos + 7], 'big')
            if height == 0:
                # The height would come in a DNL marker after the first scan: unbounded until then.
                raise ImageError('JPEG with its height deferred to a DNL marker is not supported')
            return width, height
        if length < 2:
            raise ImageError(f'JPEG header: segment FF{marker:02X} of length {length}')
        pos += length


def _tiff_size(buf: bytes) -> tuple[int, int]:
    """Width and height from the first image file directory of a classic TIFF."""
    order: Literal['little', 'big'] = 'little' if buf[:2] == b'II' else 'big'

    def number(at: int, size: int) -> int:
        if at + size > len(buf):
            raise ImageError(f'truncated TIFF header: {len(buf)} bytes')
        return int.from_bytes(buf[at : at + size], order)

    ifd = number(4, 4)
    sizes: dict[int, int] = {}
    for entry in range(ifd + 2, ifd + 2 + 12 * number(ifd, 2), 12):
        tag, kind = number(entry, 2), number(entry + 2, 2)
        if tag in (256, 257):  # ImageWidth, ImageLength: SHORT (3) or LONG (4)
            sizes[tag] = number(entry + 8, 2 if kind == 3 else 4)
    if len(sizes) < 2:
        raise ImageError('TIFF header: no ImageWidth and ImageLength in the first directory')
    return sizes[256], sizes[257]


def image_size(data: bytes | npt.NDArray[np.uint8]) -> tuple[str, int, int]:
    """Read an encoded image's kind and dimensions from its header, without decoding it.

    Knows PNG (IHDR), JPEG (the first start-of-frame segment), BMP and classic TIFF.

    Args:
        data: The file's bytes, from the start (the whole file, or at least its header).

    Returns:
        ``(kind, width, height)`` with kind one of ``"png"``, ``"jpeg"``, ``"bmp"``, ``"tiff"``.

    Raises:
        ImageError: Not one of those formats, or a truncated or inconsistent header.

    """
    buf = data.tobytes() if isinstance(data, np.ndarray) else bytes(data)
    if buf.startswith(_PNG_MAGIC):
        if len(buf) < 24 or buf[12:16] != b'IHDR':
            raise ImageError(f'truncated PNG header: {len(buf)} bytes without an IHDR chunk')
        return 'png', int.from_bytes(buf[16:20], 'big'), int.from_bytes(buf[20:24], 'big')
    if buf.startswith(_JPEG_MAGIC):
        return ('jpeg', *_jpeg_size(buf))
    if buf.startswith(b'BM') and len(buf) >= 26:
        if int.from_bytes(buf[14:18], 'little') == 12:  # OS/2 BITMAPCOREHEADER: 16-bit sizes
            return 'bmp', int.from_bytes(buf[18:20], 'little'), int.from_bytes(buf[20:22], 'little')
        width = int.from_bytes(buf[18:22], 'little', signed=True)
        # A negative height means rows stored top-down.
        return 'bmp', width, abs(int.from_bytes(buf[22:26], 'little', signed=True))
    if buf[:4] in (b'II*\x00', b'MM\x00*'):
        return ('tiff', *_tiff_size(buf))
    raise ImageError(f'not a PNG, JPEG, BMP or TIFF header (starts with {buf[:8].hex(" ")})')


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


def decode_compressed(msg: Any, max_pixels: int = DEFAULT_MAX_PIXELS) -> npt.NDArray[Any]:
    """Decode a ``sensor_msgs/CompressedImage`` holding JPEG or PNG.

    The container is recognised by its signature; ``format`` may be ``"jpeg"``, ``"png"`` or the
    image_transport form ``"rgb8; jpeg compressed bgr8"`` (``compressedDepth`` PNGs too).

    Args:
        msg: An object with ``format`` and ``data``.
        max_pixels: Largest ``width * height`` decoded; the header is read before the decoder runs.

    Returns:
        HxWx3 uint8 RGB for colour images, HxW uint8 or uint16 for grey ones.

    Raises:
        ImageError: Empty, truncated or undecodable data, over the pixel limit, or a format other
            than JPEG/PNG.

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
        _, width, height = image_size(stream[:_HEADER_BYTES])
    except ImageError as exc:
        raise ImageError(
            f'cannot decode the {stream.size}-byte {kind.upper()} data: {exc}'
        ) from None
    check_pixels(width, height, max_pixels, kind.upper())
    try:
        img = cv2.imdecode(stream, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageError(f'OpenCV cannot decode the {kind.upper()} data: {exc}') from None
    if img is None or img.size == 0:
        raise ImageError(f'OpenCV cannot decode the {stream.size}-byte {kind.upper()} data')
    if img.shape[:2] != (height, width):
        raise ImageError(
            f'{kind.upper()} header says {width}x{height} but the image decodes to '
            f'{img.shape[1]}x{img.shape[0]}'
        )
    if img.ndim == 3 and img.dtype == np.uint16:
        img = (img // 257).astype(np.uint8)
    if img.ndim == 2:
        return np.asarray(img)
    if img.shape[2] == 4:
        return _u8(cv2.cvtColor(img, cv2.COLOR_BGRA2RGB))
    return _u8(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))


def decode_image(msg: Any, max_pixels: int = DEFAULT_MAX_PIXELS) -> npt.NDArray[Any]:
    """Decode either image message: a CompressedImage (has ``format``) or an Image.

    Args:
        msg: The message.
        max_pixels: Largest ``width * height`` decoded (see :data:`DEFAULT_MAX_PIXELS`).

    Raises:
        ImageError: The message cannot be decoded or is over the pixel limit; the text says why.

    """
    if hasattr(msg, 'format'):
        return decode_compressed(msg, max_pixels)
    return decode_raw(msg, max_pixels)
