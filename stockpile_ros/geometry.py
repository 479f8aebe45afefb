"""Similarity transforms shared by reconstruction (scale, ground alignment) and evaluation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ['Similarity', 'umeyama']

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Similarity:
    """``y = scale * rotation @ x + translation``."""

    scale: float
    rotation: F64
    translation: F64

    def apply(self, points: F64) -> F64:
        """Transform Nx3 points."""
        return np.asarray(self.scale * points @ self.rotation.T + self.translation)


def umeyama(src: F64, dst: F64) -> Similarity:
    """Least-squares similarity taking ``src`` onto ``dst`` (Umeyama 1991), both Nx3, N >= 3."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    u, sig, vt = np.linalg.svd(cov)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1.0
    rot = u @ sign @ vt
    var_s = float(np.mean(np.sum(xs**2, axis=1)))
    scale = float(np.trace(np.diag(sig) @ sign)) / var_s
    return Similarity(scale, rot, mu_d - scale * rot @ mu_s)
