"""Procedural noise: lattice value noise, and a precomputed periodic noise volume for lookups."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ['NoiseVolume', 'value_noise']

# A fixed lattice table: the noise is deterministic; callers vary it by offsetting coordinates.
_TABLE_SIZE = 256
_PERM = np.random.default_rng(20240611).permutation(_TABLE_SIZE).astype(np.int64)
_VALUES = np.random.default_rng(20240612).random(_TABLE_SIZE)


def _lattice(
    ix: npt.NDArray[np.int64], iy: npt.NDArray[np.int64], iz: npt.NDArray[np.int64]
) -> npt.NDArray[np.float64]:
    m = _TABLE_SIZE - 1
    return np.asarray(_VALUES[_PERM[(_PERM[(_PERM[ix & m] + iy) & m] + iz) & m]])


def _smooth(t: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return t * t * (3.0 - 2.0 * t)


def value_noise(points: npt.ArrayLike, octaves: int = 1) -> npt.NDArray[np.float64]:
    """Smooth 3D value noise in [0, 1] with unit lattice spacing (fractal sum for ``octaves > 1``).

    Args:
        points: Nx3 coordinates in lattice units.
        octaves: Number of octaves, each at twice the frequency and half the amplitude.

    """
    p = np.asarray(points, dtype=np.float64)
    total = np.zeros(len(p))
    norm = 0.0
    for k in range(octaves):
        q = p * 2.0**k + 17.0 * k
        base = np.floor(q)
        i = base.astype(np.int64)
        w = _smooth(q - base)
        acc = np.zeros(len(p))
        for dx in (0, 1):
            wx = w[:, 0] if dx else 1.0 - w[:, 0]
            for dy in (0, 1):
                wy = w[:, 1] if dy else 1.0 - w[:, 1]
                for dz in (0, 1):
                    wz = w[:, 2] if dz else 1.0 - w[:, 2]
                    acc += wx * wy * wz * _lattice(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz)
        amp = 0.5**k
        total += amp * acc
        norm += amp
    return total / norm


class NoiseVolume:
    """A periodic cube of band-limited noise, sampled by trilinear interpolation.

    Filtering white noise in the Fourier domain gives a tileable volume whose finest detail is a few
    cells; one lookup then costs eight gathers, much cheaper than evaluating noise per ray.

    Args:
        rng: Random generator.
        size: Cells per side.
        smooth_cells: Gaussian correlation length of the noise [cells].

    """

    def __init__(self, rng: np.random.Generator, size: int = 64, smooth_cells: float = 1.2):
        white = rng.standard_normal((size, size, size))
        k = np.fft.fftfreq(size)
        k2 = k[:, None, None] ** 2 + k[None, :, None] ** 2 + k[None, None, :] ** 2
        spectrum = np.fft.fftn(white) * np.exp(-2.0 * (np.pi * smooth_cells) ** 2 * k2)
        vol = np.real(np.fft.ifftn(spectrum))
        vol = (vol - vol.mean()) / (vol.std() + 1e-12)
        self.size = size
        self.flat = vol.astype(np.float32).reshape(-1)

    def sample(
        self,
        x: npt.NDArray[np.float32],
        y: npt.NDArray[np.float32],
        z: npt.NDArray[np.float32],
    ) -> npt.NDArray[np.float32]:
        """Noise of zero mean and unit variance at points given by coordinate arrays, in cells.

        Coordinates come as separate 1D arrays: numpy is several times faster on long 1D arrays than
        on Nx3 ones, whose inner loops are three elements long.
        """
        n = self.size
        fx, fy, fz = np.floor(x), np.floor(y), np.floor(z)
        wx, wy, wz = x - fx, y - fy, z - fz
        ix, iy, iz = (f.astype(np.int64) % n for f in (fx, fy, fz))
        jx, jy, jz = (ix + 1) % n, (iy + 1) % n, (iz + 1) % n
        out = np.zeros(len(x), dtype=np.float32)
        for xs, ax in ((ix, 1 - wx), (jx, wx)):
            for ys, ay in ((iy, 1 - wy), (jy, wy)):
                plane = (xs * n + ys) * n
                low = self.flat[plane + iz]
                high = self.flat[plane + jz]
                out += (ax * ay) * (low + wz * (high - low))
        return out
