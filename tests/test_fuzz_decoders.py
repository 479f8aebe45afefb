"""Property-based fuzzing of the image decoders and the PLY reader, on a fixed budget.

Whatever the header fields and bytes, only the module's own error may come out, and no more
memory may be allocated than the pixel limit allows (numpy buffers are traced by tracemalloc).
"""

from __future__ import annotations

import contextlib
import struct
import tempfile
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stockpile_ros.meshio import LabelledMesh, MeshError, read_labelled_mesh, write_labelled_mesh
from stockpile_ros.ros.images import RAW_ENCODINGS, ImageError, decode_compressed, decode_raw

LIMIT = 4096  # pixels
# The largest image within the limit is 4096 px x 4 channels x 2 bytes; every copy on the way
# (row view, byte-order conversion, colour conversion) together stays well under a megabyte.
PEAK_BOUND = 1 << 20
BUDGET = settings(max_examples=1000, deadline=None, derandomize=True)

UINT32 = st.integers(0, 2**32 - 1)


def _traced(call: Callable[[], object]) -> int:
    """Run ``call`` and return the peak of traced memory [bytes]."""
    tracemalloc.start()
    try:
        call()
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return peak


def _only(error: type[Exception], call: Callable[[], object]) -> None:
    """Run ``call`` under tracemalloc: it returns or raises ``error``, within the peak bound."""

    def guarded() -> None:
        with contextlib.suppress(error):
            call()

    assert _traced(guarded) < PEAK_BOUND


@BUDGET
@given(
    encoding=st.sampled_from([*RAW_ENCODINGS, 'RGB8', 'weird', '']),
    width=st.one_of(st.integers(0, 80), UINT32),
    height=st.one_of(st.integers(0, 80), UINT32),
    step=st.one_of(st.integers(0, 400), UINT32),
    data=st.binary(max_size=8192),
    bigendian=st.booleans(),
)
def test_raw_decoder_raises_only_image_error(
    encoding: str, width: int, height: int, step: int, data: bytes, bigendian: bool
) -> None:
    msg = SimpleNamespace(
        encoding=encoding, width=width, height=height, step=step,
        data=np.frombuffer(data, np.uint8), is_bigendian=int(bigendian),
    )  # fmt: skip
    _only(ImageError, lambda: decode_raw(msg, LIMIT))


def _encoded(ext: str, size: tuple[int, int]) -> bytes:
    ok, buf = cv2.imencode(ext, np.full((*size, 3), 120, np.uint8))
    assert ok
    return buf.tobytes()


SEEDS = [_encoded('.png', (8, 8)), _encoded('.jpg', (8, 8)), _encoded('.jpg', (64, 64))]


@st.composite
def _mutated(draw: Any) -> bytes:
    """A valid PNG or JPEG with bytes overwritten, cut off or with a header field rewritten."""
    data = bytearray(draw(st.sampled_from(SEEDS)))
    for _ in range(draw(st.integers(0, 4))):
        at = draw(st.integers(0, len(data) - 1))
        data[at] = draw(st.integers(0, 255))
    if draw(st.booleans()):  # a large size in the header, the body left as it is
        size = struct.pack('>HH', draw(st.integers(0, 65535)), draw(st.integers(0, 65535)))
        at = data.find(b'\xff\xc0')
        if data.startswith(b'\x89PNG'):
            data[16:24] = struct.pack('>II', draw(UINT32), draw(UINT32))
        elif at >= 0:
            data[at + 5 : at + 9] = size
    return bytes(data[: draw(st.integers(0, len(data)))])


@BUDGET
@given(
    fmt=st.sampled_from(['jpeg', 'png', 'rgb8; jpeg compressed bgr8', '16UC1; compressedDepth']),
    data=st.one_of(st.binary(max_size=512), _mutated()),
)
def test_compressed_decoder_raises_only_image_error(fmt: str, data: bytes) -> None:
    msg = SimpleNamespace(format=fmt, data=np.frombuffer(data, np.uint8))
    _only(ImageError, lambda: decode_compressed(msg, LIMIT))


def _valid_ply() -> bytes:
    rng = np.random.default_rng(0)
    faces = np.array([[0, 1, 2], [2, 3, 4], [3, 4, 5]])
    colors = rng.integers(0, 255, (6, 3), np.uint8)
    mesh = LabelledMesh(rng.random((6, 3)), faces, np.array([1, 1, 2], np.int32), colors)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / 'm.ply'
        write_labelled_mesh(path, mesh)
        return path.read_bytes()


VALID_PLY = _valid_ply()
HEADER_END = VALID_PLY.index(b'end_header') + len(b'end_header\n')


@st.composite
def _mutated_ply(draw: Any) -> bytes:
    """The valid PLY with header words replaced, bytes overwritten or the file cut off."""
    data = bytearray(VALID_PLY)
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, HEADER_END - 1))
        data[at] = draw(st.sampled_from(b'0123456789 \n\rxyzabcdefghijklmnopqrstuvw\x00\xff'))
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, len(data) - 1))
        data[at] = draw(st.integers(0, 255))
    if draw(st.booleans()):
        count = str(draw(st.integers(0, 10**15))).encode()
        data = bytearray(bytes(data).replace(b'vertex 6', b'vertex ' + count, 1))
    return bytes(data[: draw(st.integers(0, len(data)))])


@BUDGET
@given(data=st.one_of(st.binary(max_size=512).map(lambda b: b'ply\n' + b), _mutated_ply()))
def test_ply_reader_raises_only_mesh_error(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / 'm.ply'
        path.write_bytes(data)
        _only(MeshError, lambda: read_labelled_mesh(path))
