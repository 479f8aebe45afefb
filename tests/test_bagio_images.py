from __future__ import annotations

import array
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
import pytest

from stockpile_ros.errors import StockpileError
from stockpile_ros.ros.images import ImageError, decode_compressed, decode_image, decode_raw

RNG = np.random.default_rng(3)
RGB = RNG.integers(0, 256, (5, 7, 3), dtype=np.uint8)


def raw(img: np.ndarray, encoding: str, pad: int = 0, bigendian: bool = False) -> Any:
    """A sensor_msgs/Image look-alike whose rows carry ``pad`` junk bytes each."""
    h, w = img.shape[:2]
    rows = img.reshape(h, -1).view(np.uint8).reshape(h, -1)
    junk = np.full((h, pad), 0xAB, dtype=np.uint8)
    data = np.concatenate([rows, junk], axis=1).reshape(-1)
    return SimpleNamespace(
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=int(bigendian),
        step=rows.shape[1] + pad,
        data=data,
    )


def compressed(img: np.ndarray, ext: str, fmt: str) -> Any:
    bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR) if img.ndim == 3 else img
    ok, buf = cv2.imencode(ext, bgr)
    assert ok
    return SimpleNamespace(format=fmt, data=buf.reshape(-1))


@pytest.mark.parametrize('pad', [0, 3])
@pytest.mark.parametrize(
    ('encoding', 'make'),
    [
        ('rgb8', lambda rgb: rgb),
        ('bgr8', lambda rgb: rgb[:, :, ::-1]),
        ('rgba8', lambda rgb: np.dstack([rgb, np.full(rgb.shape[:2], 9, np.uint8)])),
        ('bgra8', lambda rgb: np.dstack([rgb[:, :, ::-1], np.full(rgb.shape[:2], 9, np.uint8)])),
    ],
)
def test_colour_encodings_give_rgb(encoding: str, make: Any, pad: int) -> None:
    out = decode_raw(raw(np.ascontiguousarray(make(RGB)), encoding, pad))
    assert out.dtype == np.uint8 and out.shape == (5, 7, 3)
    assert np.array_equal(out, RGB)


@pytest.mark.parametrize('encoding', ['mono8', '8UC1'])
def test_mono8_with_padding(encoding: str) -> None:
    grey = RGB[:, :, 0].copy()
    out = decode_raw(raw(grey, encoding, pad=5))
    assert out.dtype == np.uint8 and np.array_equal(out, grey)


@pytest.mark.parametrize('encoding', ['mono16', '16UC1'])
@pytest.mark.parametrize('bigendian', [False, True])
def test_mono16_honours_byte_order(encoding: str, bigendian: bool) -> None:
    depth = RNG.integers(0, 65536, (4, 6)).astype(np.uint16)
    stored = depth.astype('>u2' if bigendian else '<u2')
    out = decode_raw(raw(stored, encoding, pad=2, bigendian=bigendian))
    assert out.dtype == np.uint16 and np.array_equal(out, depth)
    # Reading big-endian data as little-endian would swap the bytes: the flag matters.
    if bigendian:
        msg = raw(stored, encoding, pad=2, bigendian=False)
        assert not np.array_equal(decode_raw(msg), depth)


@pytest.mark.parametrize('pattern', ['rggb', 'bggr', 'gbrg', 'grbg'])
def test_bayer_patterns_demosaic_to_the_true_colour(pattern: str) -> None:
    colour = {'r': 200, 'g': 100, 'b': 30}
    mosaic = np.zeros((8, 10), dtype=np.uint8)
    for (dy, dx), channel in zip([(0, 0), (0, 1), (1, 0), (1, 1)], pattern, strict=True):
        mosaic[dy::2, dx::2] = colour[channel]
    out = decode_raw(raw(mosaic, f'bayer_{pattern}8', pad=2))
    assert out.shape == (8, 10, 3)
    assert out[2:-2, 2:-2].reshape(-1, 3).tolist() == [[200, 100, 30]] * 24


@pytest.mark.parametrize(('encoding', 'order'), [('yuv422', 'uyvy'), ('yuv422_yuy2', 'yuyv')])
def test_yuv422_byte_order(encoding: str, order: str) -> None:
    y, u, v = 150, 128, 200  # a red chroma: only the right byte order gives a red image
    pair = [u, y, v, y] if order == 'uyvy' else [y, u, y, v]
    data = np.tile(np.array(pair, np.uint8), (3, 2)).reshape(3, 4, 2)  # 3 rows of 4 pixels
    out = decode_raw(raw(data, encoding)).astype(int)
    assert out.shape == (3, 4, 3)
    # BT.601 limited range: G = 1.164 (Y - 16) - 0.813 (V - 128) = 97.
    assert np.all(out[..., 0] == 255) and np.all(np.abs(out[..., 1] - 97) <= 2)


def test_rclpy_style_data_containers() -> None:
    grey = RGB[:, :, 1].copy()
    msg = raw(grey, 'mono8')
    for container in (bytes(msg.data), array.array('B', bytes(msg.data)), list(msg.data)):
        msg.data = container
        assert np.array_equal(decode_image(msg), grey)


def test_decoded_image_is_writable_copy() -> None:
    msg = raw(RGB, 'rgb8')
    msg.data = bytes(msg.data)
    out = decode_raw(msg)
    out[0, 0] = 0
    assert out.flags.writeable


def test_last_row_padding_may_be_missing() -> None:
    msg = raw(RGB, 'rgb8', pad=4)
    msg.data = msg.data[:-4]
    assert np.array_equal(decode_raw(msg), RGB)


def test_short_data_names_sizes() -> None:
    msg = raw(RGB, 'rgb8')
    msg.data = msg.data[:30]
    with pytest.raises(
        ImageError, match=r'data holds 30 bytes but 7x5 rgb8 with step 21 needs 105'
    ):
        decode_raw(msg)


@pytest.mark.parametrize(
    ('change', 'message'),
    [
        ({'encoding': '32FC1'}, "unsupported image encoding '32FC1'"),
        ({'encoding': 'bayer_rggb16'}, 'unsupported image encoding'),
        ({'height': 0}, 'empty image: 7x0'),
        ({'step': 20}, 'step 20 is smaller than one row'),
    ],
)
def test_malformed_raw_images(change: dict[str, Any], message: str) -> None:
    msg = raw(RGB, 'rgb8')
    for key, value in change.items():
        setattr(msg, key, value)
    with pytest.raises(ImageError, match=message):
        decode_raw(msg)


def test_errors_are_user_errors() -> None:
    assert issubclass(ImageError, StockpileError) and issubclass(ImageError, ValueError)


@pytest.mark.parametrize(
    'fmt', ['png', 'rgb8; png compressed bgr8', 'bgr8; png compressed bgr8', 'PNG']
)
def test_png_is_lossless(fmt: str) -> None:
    assert np.array_equal(decode_compressed(compressed(RGB, '.png', fmt)), RGB)


@pytest.mark.parametrize('fmt', ['jpeg', 'rgb8; jpeg compressed bgr8', 'jpg'])
def test_jpeg_colours_come_back_in_rgb_order(fmt: str) -> None:
    flat = np.zeros((16, 16, 3), np.uint8)
    flat[:] = (220, 40, 10)
    out = decode_compressed(compressed(flat, '.jpg', fmt))
    assert out.shape == (16, 16, 3)
    assert np.abs(out.astype(int) - [220, 40, 10]).max() <= 6


def test_grey_png_and_16_bit_png() -> None:
    grey = RGB[:, :, 2].copy()
    assert np.array_equal(decode_compressed(compressed(grey, '.png', 'mono8; png')), grey)
    depth = RNG.integers(0, 65536, (4, 6)).astype(np.uint16)
    out = decode_compressed(compressed(depth, '.png', 'png'))
    assert out.dtype == np.uint16 and np.array_equal(out, depth)


def test_compressed_depth_header_is_skipped() -> None:
    depth = RNG.integers(0, 65536, (4, 6)).astype(np.uint16)
    msg = compressed(depth, '.png', '16UC1; compressedDepth png')
    msg.data = np.concatenate([np.zeros(12, np.uint8), msg.data])
    assert np.array_equal(decode_compressed(msg), depth)


def test_truncated_jpeg() -> None:
    msg = compressed(RGB, '.jpg', 'jpeg')
    msg.data = msg.data[: msg.data.size // 2]
    with pytest.raises(ImageError, match='truncated JPEG'):
        decode_compressed(msg)
    # The 10-byte JFIF head of the fixture bags.
    msg.data = np.frombuffer(b'\xff\xd8\xff\xe0\x00\x10JFIF', np.uint8)
    with pytest.raises(ImageError, match='truncated JPEG: 10 bytes'):
        decode_compressed(msg)


def test_truncated_png() -> None:
    msg = compressed(RGB, '.png', 'png')
    msg.data = msg.data[:-20]
    with pytest.raises(ImageError, match='truncated PNG'):
        decode_compressed(msg)


def test_corrupt_jpeg_body() -> None:
    msg = SimpleNamespace(
        format='jpeg', data=np.frombuffer(b'\xff\xd8\xff' + b'\x00' * 40 + b'\xff\xd9', np.uint8)
    )
    with pytest.raises(ImageError, match='cannot decode'):
        decode_compressed(msg)


@pytest.mark.parametrize(
    ('fmt', 'data', 'message'),
    [
        ('jpeg', b'', 'holds no data'),
        ('jpeg', b'GIF89a......', 'neither JPEG nor PNG'),
        ('theora', b'\x80theora', "unsupported compressed format 'theora'"),
    ],
)
def test_malformed_compressed(fmt: str, data: bytes, message: str) -> None:
    with pytest.raises(ImageError, match=message):
        decode_compressed(SimpleNamespace(format=fmt, data=np.frombuffer(data, np.uint8)))
