"""Surface colours: solid noise textures per rock, tiled gravel on the ground, a ChArUco board.

Structure-from-Motion needs texture at the scale of a few pixels, so every surface carries detail
from centimetres down to millimetres; solid textures need no UV map and do not stretch on any facet.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
import scipy.fft

from .noise import NoiseVolume

__all__ = ['BoardTexture', 'GroundTexture', 'RockTextures', 'charuco_board', 'lookup']

# Rock palettes, linear RGB: grey granite, brown sandstone, dark basalt, pink granite, limestone.
_PALETTES = np.array(
    [
        [0.24, 0.24, 0.23],
        [0.30, 0.23, 0.16],
        [0.11, 0.11, 0.11],
        [0.32, 0.24, 0.21],
        [0.36, 0.34, 0.30],
    ]
)

# Albedo of the board's paper and ink: neither perfectly white nor perfectly black.
_PAPER = 0.84
_INK = 0.04

# cv2.remap wants maps narrower than 32767 columns: lay long point lists out in rows of this width.
_ROW = 4096


def lookup(
    image: npt.NDArray[np.float32],
    u: npt.NDArray[np.floating],
    v: npt.NDArray[np.floating],
    border: int,
    border_value: float = 0.0,
) -> npt.NDArray[np.float32]:
    """Bilinear lookup of ``image`` at pixel coordinates (u: column, v: row), one value per point.

    Returns:
        N x channels (or N for a single-channel image) float32 values.

    """
    n = len(u)
    rows = max(1, -(-n // _ROW))
    if n == rows * _ROW:
        map_u = np.asarray(u, dtype=np.float32).reshape(rows, _ROW)
        map_v = np.asarray(v, dtype=np.float32).reshape(rows, _ROW)
    else:
        maps = np.zeros((2, rows * _ROW), dtype=np.float32)
        maps[0, :n] = u
        maps[1, :n] = v
        map_u, map_v = maps[0].reshape(rows, _ROW), maps[1].reshape(rows, _ROW)
    out = cv2.remap(
        image,
        map_u,
        map_v,
        cv2.INTER_LINEAR,
        borderMode=border,
        borderValue=border_value,
    )
    channels = out.shape[2:] if out.ndim == 3 else ()
    return np.asarray(out.reshape(rows * _ROW, *channels)[:n], dtype=np.float32)


class RockTextures:
    """Solid textures for every rock: a base colour, centimetre blotches and millimetre grains.

    Args:
        rng: Random generator.
        n_rocks: Number of rocks (ids 1..n).
        blotch: Size of the colour blotches [m].
        grain: Size of the mineral grains [m].
        bump: Size of the surface relief bumps [m].
        bump_slope: Typical slope of the relief (shading normals tilt by about this much).

    """

    def __init__(
        self,
        rng: np.random.Generator,
        n_rocks: int,
        blotch: float = 0.03,
        grain: float = 0.003,
        bump: float = 0.006,
        bump_slope: float = 0.25,
    ):
        self.volume = NoiseVolume(rng, size=64, smooth_cells=1.0)
        picks = rng.integers(0, len(_PALETTES), size=n_rocks + 1)
        tint = rng.uniform(0.95, 1.05, size=(n_rocks + 1, 3)) * rng.uniform(
            0.7, 1.3, size=(n_rocks + 1, 1)
        )
        self.base = (_PALETTES[picks] * tint).astype(np.float32)
        self.grain_colour = (self.base * rng.uniform(0.3, 1.8, size=(n_rocks + 1, 1))).astype(
            np.float32
        )
        self.offset = rng.uniform(0, 64, size=(n_rocks + 1, 3)).astype(np.float32)
        self.blotch = blotch
        self.grain = grain
        self.bump = bump
        self.bump_slope = bump_slope

    def albedo(
        self,
        x: npt.NDArray[np.float32],
        y: npt.NDArray[np.float32],
        z: npt.NDArray[np.float32],
        rock_ids: npt.NDArray[np.int64],
    ) -> npt.NDArray[np.float32]:
        """Linear RGB albedo (Nx3) at world points (coordinate arrays) on rocks ``rock_ids``."""
        ox, oy, oz = (self.offset[rock_ids, k] for k in range(3))
        cb, cg = 1.0 / self.blotch, 1.0 / self.grain
        coarse = self.volume.sample(x * cb + ox, y * cb + oy, z * cb + oz)
        fine = self.volume.sample(x * cg + 2.7 * ox, y * cg + 2.7 * oy, z * cg + 2.7 * oz)
        shade = np.clip(1.0 + 0.35 * coarse + 0.2 * fine, 0.25, 2.0)
        grains = np.clip((fine - 0.9) * 2.0, 0.0, 1.0)
        out = np.empty((len(x), 3), dtype=np.float32)
        for k in range(3):
            base = self.base[rock_ids, k]
            out[:, k] = base * shade * (1 - grains) + self.grain_colour[rock_ids, k] * grains
        return out

    def relief(
        self,
        x: npt.NDArray[np.float32],
        y: npt.NDArray[np.float32],
        z: npt.NDArray[np.float32],
        rock_ids: npt.NDArray[np.int64],
    ) -> list[npt.NDArray[np.float32]]:
        """Gradient of a solid bump field (unitless slope) at world points on rocks ``rock_ids``.

        Perturbing shading normals by it gives millimetre relief that a 5000-face mesh lacks.
        """
        scale = 1.0 / self.bump
        o = [self.offset[rock_ids, k] * np.float32(1.9) for k in range(3)]
        q = [x * scale + o[0], y * scale + o[1], z * scale + o[2]]
        h = np.float32(0.35)  # finite-difference step [cells]
        here = self.volume.sample(q[0], q[1], q[2])
        grad = []
        for k in range(3):
            moved = [q[0], q[1], q[2]]
            moved[k] = q[k] + h
            grad.append((self.volume.sample(*moved) - here) * np.float32(self.bump_slope / h))
        return grad


class GroundTexture:
    """A tileable gravel-and-soil texture lying on the ground plane, looked up by world x, y.

    Args:
        rng: Random generator.
        size: Texture side [px].
        texel: Size of one texel [m].

    """

    def __init__(self, rng: np.random.Generator, size: int = 2048, texel: float = 0.002):
        # One white-noise spectrum filtered to several scales: soil patches, gravel, grit, pebbles.
        spectrum = scipy.fft.rfft2(rng.standard_normal((size, size), dtype=np.float32))
        k2 = (
            np.fft.fftfreq(size).astype(np.float32)[:, None] ** 2
            + np.fft.rfftfreq(size).astype(np.float32)[None, :] ** 2
        )

        def band(corr_px: float) -> npt.NDArray[np.float32]:
            b = scipy.fft.irfft2(
                spectrum * np.exp(-2.0 * (np.pi * corr_px) ** 2 * k2), s=(size, size)
            )
            return np.asarray((b - b.mean()) / (b.std() + 1e-12), dtype=np.float32)

        tone = 1.0 + 0.15 * band(40.0) + 0.18 * band(8.0) + 0.14 * band(1.2)
        pebbles = band(2.5)
        light = np.clip((pebbles - 1.5) * 3.0, 0.0, 1.0)
        dark = np.clip((-pebbles - 2.0) * 3.0, 0.0, 1.0)
        soil = np.array([0.20, 0.16, 0.115], dtype=np.float32)
        img = soil[None, None, :] * tone[:, :, None]
        img = (
            img * (1 - light[..., None])
            + np.array([0.38, 0.36, 0.33], dtype=np.float32) * light[..., None]
        )
        img = (
            img * (1 - dark[..., None])
            + np.array([0.06, 0.055, 0.05], dtype=np.float32) * dark[..., None]
        )
        self.image = np.ascontiguousarray(np.clip(img, 0, 1), dtype=np.float32)
        self.texel = texel
        self.size = size

    def albedo(
        self, x: npt.NDArray[np.float32], y: npt.NDArray[np.float32]
    ) -> npt.NDArray[np.float32]:
        """Linear RGB albedo (Nx3) at world ground points given by coordinate arrays."""
        inv = 1.0 / self.texel
        return lookup(self.image, x * inv, y * inv, cv2.BORDER_WRAP).reshape(-1, 3)


@dataclass(frozen=True)
class BoardTexture:
    """A printed ChArUco board lying face-up on the ground.

    Attributes:
        squares_x: Squares along the board's x.
        squares_y: Squares along the board's y.
        square_length: Side of one square [m].
        marker_length: Side of one marker [m].
        dictionary: OpenCV ArUco dictionary name, e.g. ``"DICT_4X4_50"``.
        origin: World position of the board's top-left corner (board x = y = 0) [m].
        yaw: Rotation of the board's x axis from world x about z [rad].
        margin: White paper around the printed pattern [m].
        px_per_m: Resolution of the printed image.

    """

    squares_x: int = 5
    squares_y: int = 4
    square_length: float = 0.08
    marker_length: float = 0.06
    dictionary: str = 'DICT_4X4_50'
    origin: tuple[float, float] = (0.0, 0.0)
    yaw: float = 0.0
    margin: float = 0.03
    px_per_m: float = 2000.0

    def axes(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """World directions of the board's x and y (x cross y points down, as OpenCV's board z)."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.array([c, s, 0.0]), np.array([s, -c, 0.0])

    def size(self) -> tuple[float, float]:
        """Board extent along its x and y [m]."""
        return self.squares_x * self.square_length, self.squares_y * self.square_length

    def to_world(self, board_xy: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """World points (z = 0) of board-plane points Nx2 [m]."""
        ex, ey = self.axes()
        o = np.array([self.origin[0], self.origin[1], 0.0])
        return np.asarray(o + board_xy[:, :1] * ex + board_xy[:, 1:2] * ey)

    def corner_quad(self) -> npt.NDArray[np.float64]:
        """Return the four corners of the paper (margin included) in world coordinates."""
        w, h = self.size()
        m = self.margin
        return self.to_world(np.array([[-m, -m], [-m, h + m], [w + m, h + m], [w + m, -m]]))

    def charuco_corners_world(self) -> npt.NDArray[np.float64]:
        """World positions of the inner chessboard corners, in ChArUco corner id order."""
        board = charuco_board(self)
        return self.to_world(np.asarray(board.getChessboardCorners())[:, :2].astype(np.float64))

    def image(self) -> npt.NDArray[np.float32]:
        """Return the printed board as a float image in [0, 1] (rows along board y)."""
        w, h = self.size()
        px = (round(w * self.px_per_m), round(h * self.px_per_m))
        img = charuco_board(self).generateImage(px, marginSize=0, borderBits=1)
        # Paper is not perfectly white nor ink perfectly black.
        return np.asarray(
            _INK + (_PAPER - _INK) * (img.astype(np.float32) / 255.0), dtype=np.float32
        )

    def lookup(
        self, image: npt.NDArray[np.float32], x: npt.NDArray[np.float32], y: npt.NDArray[np.float32]
    ) -> npt.NDArray[np.float32]:
        """Linear RGB albedo (Nx3) of world points (x, y) on the board, given its :meth:`image`."""
        ex, ey = self.axes()
        rx, ry = x - self.origin[0], y - self.origin[1]
        u = (rx * ex[0] + ry * ex[1]) * self.px_per_m - 0.5
        v = (rx * ey[0] + ry * ey[1]) * self.px_per_m - 0.5
        grey = lookup(image, u, v, cv2.BORDER_CONSTANT, _PAPER).reshape(-1)
        return np.repeat(grey[:, None], 3, axis=1)


def charuco_board(spec: BoardTexture) -> cv2.aruco.CharucoBoard:
    """Return the OpenCV board object of ``spec``."""
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec.dictionary))
    return cv2.aruco.CharucoBoard(
        (spec.squares_x, spec.squares_y), spec.square_length, spec.marker_length, dictionary
    )
