"""Intrinsics of photos from their EXIF tags, as the prior Structure-from-Motion starts from.

A camera's focal length in pixels is the lens focal length over the sensor width times the image
width. Phones and most cameras write ``FocalLengthIn35mmFilm`` (the focal length a 36 x 24 mm
frame would need for the same field of view, by the diagonal as CIPA DC-008 defines it); where only
``FocalLength`` is there, the sensor's size comes from ``FocalPlaneXResolution`` or from a small
table of common camera families. Without either the camera is self-calibrated. The prior is
refined by bundle adjustment, so a table entry a few percent off does no harm; none at all made
the real 16-photo set of the field notes fall apart into three models.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from PIL import Image

from ..errors import StockpileError

__all__ = ['HEIF_SUFFIXES', 'PhotoIntrinsics', 'open_photo', 'read_intrinsics', 'sensor_width']

HEIF_SUFFIXES = ('.heic', '.heif')

_EXIF_IFD = 0x8769
_MAKE, _MODEL = 0x010F, 0x0110
_FOCAL, _FOCAL_35 = 0x920A, 0xA405
_PLANE_X, _PLANE_UNIT, _EXIF_WIDTH, _EXIF_HEIGHT = 0xA20E, 0xA210, 0xA002, 0xA003
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0}  # FocalPlaneResolutionUnit: inch, cm, mm -> mm per unit
_FULL_FRAME_DIAGONAL = math.hypot(36.0, 24.0)

# (make, model pattern, sensor width [mm]) of camera families that may write no 35 mm
# equivalent; the first match wins, so full-frame bodies come before the same maker's APS-C ones.
_SENSORS: tuple[tuple[str, str, float], ...] = (
    ('canon', r'eos[- ](1d|5d|6d|r|r3|r5|r6|r8|ra)\b', 36.0),
    ('canon', r'eos', 22.3),
    ('canon', r'powershot g(1 x mark iii|5 x|7 x|9 x)', 13.2),
    ('nikon', r'\b(d[3-6][sx]?|d[678]\d0e?|df|z ?[5-9]\w*)$', 35.9),
    ('nikon', r'\b(d\d{2,4}x?|z ?(30|50|fc))$', 23.5),
    ('sony', r'ilce-(7|9|1\b)', 35.8),
    ('sony', r'(ilce-\d|nex|slt|dslr)', 23.5),
    ('sony', r'dsc-rx(100|10)', 13.2),
    ('fujifilm', r'^x-', 23.5),
    ('olympus', r'', 17.3),
    ('om digital', r'', 17.3),
    ('panasonic', r'(dmc|dc)-(g|gh|gx)', 17.3),
    ('gopro', r'', 6.17),
)


def sensor_width(make: str, model: str) -> float | None:
    """Sensor width [mm] of a camera family of the table, None when it is not there."""
    make_l, model_l = make.strip().lower(), model.strip().lower()
    for maker, pattern, width in _SENSORS:
        if maker in make_l and re.search(pattern, model_l):
            return width
    return None


@dataclass(frozen=True)
class PhotoIntrinsics:
    """What a photo's EXIF says about its camera.

    Attributes:
        file: File name in the photo folder.
        width: Image width [px], as stored (before any EXIF rotation).
        height: Image height [px].
        make: Camera maker, '' when not given.
        model: Camera model, '' when not given.
        focal_mm: ``FocalLength`` [mm], None when not given.
        focal_35mm: ``FocalLengthIn35mmFilm`` [mm], None when not given.
        focal_px: Focal length [px] derived from them, None when it cannot be.
        focal_source: How ``focal_px`` was found: ``35mm equivalent``, ``focal plane
            resolution``, ``sensor table``, or ``none`` (self-calibrated).

    """

    file: str
    width: int
    height: int
    make: str = ''
    model: str = ''
    focal_mm: float | None = None
    focal_35mm: float | None = None
    focal_px: float | None = None
    focal_source: str = 'none'

    def as_dict(self) -> dict[str, Any]:
        """Return the fields as a JSON-ready dict."""
        return asdict(self)


def open_photo(path: Path) -> Image.Image:
    """Open a photo lazily with Pillow (HEIC/HEIF through pillow-heif).

    Raises:
        StockpileError: A HEIC/HEIF photo and pillow-heif is not installed, or Pillow cannot
            read the file.

    """
    if path.suffix.lower() in HEIF_SUFFIXES:
        try:
            import pillow_heif
        except ImportError:
            raise StockpileError(
                f'{path}: HEIC/HEIF photos need pillow-heif (pip install pillow-heif), or '
                'convert them to JPEG, or set the phone to "Most Compatible" (JPEG)'
            ) from None
        pillow_heif.register_heif_opener()
    try:
        return Image.open(path)
    except (OSError, ValueError) as exc:
        raise StockpileError(f'{path}: unreadable photo ({exc})') from None


def _number(value: Any) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) and number > 0 else None


def read_intrinsics(path: Path) -> PhotoIntrinsics:
    """Read a photo's size and EXIF focal length and derive its focal length in pixels.

    Raises:
        StockpileError: As :func:`open_photo`.

    """
    with open_photo(path) as image:
        width, height = image.size
        exif = image.getexif()
        sub = exif.get_ifd(_EXIF_IFD)
    make, model = str(exif.get(_MAKE, '')).strip('\x00 '), str(exif.get(_MODEL, '')).strip('\x00 ')
    focal, focal_35 = _number(sub.get(_FOCAL)), _number(sub.get(_FOCAL_35))
    long_side, diagonal = max(width, height), math.hypot(width, height)
    focal_px, source = None, 'none'
    plane_x, unit = _number(sub.get(_PLANE_X)), _UNIT_MM.get(int(sub.get(_PLANE_UNIT, 2) or 2))
    exif_long = _number(max(int(sub.get(_EXIF_WIDTH, 0) or 0), int(sub.get(_EXIF_HEIGHT, 0) or 0)))
    table = sensor_width(make, model)
    if focal_35 is not None:
        focal_px, source = focal_35 / _FULL_FRAME_DIAGONAL * diagonal, '35mm equivalent'
    elif focal is not None and plane_x is not None and unit is not None:
        # Pixels per mm on the sensor at the size the camera wrote; a resized copy scales it.
        scale = long_side / exif_long if exif_long else 1.0
        focal_px, source = focal * plane_x / unit * scale, 'focal plane resolution'
    elif focal is not None and table is not None:
        focal_px, source = focal * long_side / table, 'sensor table'
    return PhotoIntrinsics(path.name, width, height, make, model, focal, focal_35, focal_px, source)
