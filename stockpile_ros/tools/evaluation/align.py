"""Align a reported camera trajectory to the true one (similarity transform of camera centres)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ...geometry import umeyama
from .inputs import EvaluationError, Poses

__all__ = [
    'COLLINEAR_RATIO',
    'Alignment',
    'align_trajectories',
    'match_stamps',
    'nearest_rotation',
    'rotation_angle',
]

FloatArray = npt.NDArray[np.float64]

# Below this ratio of the second to the first singular value of the centred keyframe centres, the
# centres are treated as collinear (a straight cart pass at one height): the rotation about that
# line is then taken from the camera orientations instead.
COLLINEAR_RATIO = 0.05


def nearest_rotation(m: npt.ArrayLike) -> FloatArray:
    """Return the proper rotation closest to the 3x3 matrix ``m`` in the Frobenius norm.

    The sum of several rotation matrices projected this way is their chordal L2 mean.
    """
    u, _, vt = np.linalg.svd(np.asarray(m, dtype=np.float64))
    sign = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(u @ vt)) or 1.0)])
    out: FloatArray = u @ sign @ vt
    return out


def rotation_angle(rot: npt.ArrayLike) -> float:
    """Angle of the rotation matrix ``rot`` [rad], in [0, pi]."""
    r = np.asarray(rot, dtype=np.float64)
    # atan2 keeps precision near 0 and pi, where arccos of the trace does not.
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return float(np.arctan2(np.linalg.norm(skew) / 2.0, (np.trace(r) - 1.0) / 2.0))


@dataclass
class Alignment:
    """Similarity transform from the result frame into the truth frame, and how well it fits.

    A result point ``x`` maps to ``scale * rotation @ x + translation`` in the truth frame.

    Attributes:
        method: ``"umeyama"`` (camera centres), ``"centres+orientations"`` (collinear centres: the
            rotation from the camera orientations, scale and translation from the centres) or
            ``"identity"`` (too few keyframes; both sides claim the same frame).
        scale: Truth metres per result unit.
        rotation: 3x3 rotation.
        translation: Translation (3,).
        keyframes: Keyframes in the report.
        matched: Keyframes matched to a true camera by stamp.
        centre_errors: Distance between each matched aligned keyframe centre and the true one [m].
        orientation_errors: Angle between each matched aligned keyframe orientation and the true one
            [rad].
        note: Why a fallback was taken, empty otherwise.

    """

    method: str
    scale: float
    rotation: FloatArray
    translation: FloatArray
    keyframes: int
    matched: int
    centre_errors: FloatArray
    orientation_errors: FloatArray
    note: str = ''

    def apply(self, points: npt.ArrayLike) -> FloatArray:
        """Map Nx3 result-frame points into the truth frame."""
        p = np.asarray(points, dtype=np.float64)
        out: FloatArray = self.scale * p @ self.rotation.T + self.translation
        return out


def match_stamps(
    result_ns: npt.NDArray[np.int64], truth_ns: npt.NDArray[np.int64], tolerance_ns: int
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Pair each result stamp with the nearest truth stamp no further than ``tolerance_ns``.

    Returns:
        Indices into ``result_ns`` and into ``truth_ns`` of the pairs, in result order.

    """
    if len(truth_ns) == 0 or len(result_ns) == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    order = np.argsort(truth_ns, kind='stable')
    sorted_ns = truth_ns[order]
    pos = np.searchsorted(sorted_ns, result_ns)
    lo = np.clip(pos - 1, 0, len(sorted_ns) - 1)
    hi = np.clip(pos, 0, len(sorted_ns) - 1)
    # Differences in int64 stay exact; float stamps in ns would not.
    d_lo = np.abs(result_ns - sorted_ns[lo])
    d_hi = np.abs(result_ns - sorted_ns[hi])
    nearest = np.where(d_hi < d_lo, hi, lo)
    dist = np.minimum(d_lo, d_hi)
    keep = np.flatnonzero(dist <= tolerance_ns)
    return keep.astype(np.intp), order[nearest[keep]].astype(np.intp)


def _residuals(
    scale: float, rot: FloatArray, trans: FloatArray, src: Poses, dst: Poses
) -> tuple[FloatArray, FloatArray]:
    aligned = scale * src.centres @ rot.T + trans
    centre_errors = np.linalg.norm(aligned - dst.centres, axis=1)
    orientation_errors = np.array(
        [
            rotation_angle(rt.T @ rot @ rr)
            for rr, rt in zip(src.rotations, dst.rotations, strict=True)
        ]
    )
    return centre_errors, orientation_errors.reshape(-1)


def _subset(poses: Poses, idx: npt.NDArray[np.intp]) -> Poses:
    return Poses(poses.stamps_ns[idx], poses.centres[idx], poses.rotations[idx])


def _with_orientations(src: Poses, dst: Poses) -> tuple[float, FloatArray, FloatArray]:
    rot = nearest_rotation(np.einsum('nij,nkj->ik', dst.rotations, src.rotations))
    xc = src.centres - src.centres.mean(axis=0)
    yc = dst.centres - dst.centres.mean(axis=0)
    scale = float(np.sum((xc @ rot.T) * yc) / np.sum(xc**2))
    if scale <= 0:
        raise EvaluationError(
            'the reported keyframes run against the true camera path (negative scale); '
            'the keyframe stamps or poses are wrong'
        )
    return scale, rot, dst.centres.mean(axis=0) - scale * rot @ src.centres.mean(axis=0)


def align_trajectories(
    keyframes: Poses,
    cameras: Poses,
    result_frame: str,
    truth_frame: str,
    tolerance_ns: int = 5_000_000,
) -> Alignment:
    """Fit the similarity transform taking reported keyframe centres onto the true camera centres.

    Keyframes are paired with true cameras by stamp (nearest within ``tolerance_ns``). With 3 or
    more pairs whose centres are not all on one line the fit is Umeyama's; collinear centres take
    the rotation from the camera orientations. With fewer pairs (or all centres at one point) the
    two sides are compared in their own frames, which is only allowed when they name the same one.

    Raises:
        EvaluationError: Too few keyframes pair up and the frames differ.

    """
    ri, ti = match_stamps(keyframes.stamps_ns, cameras.stamps_ns, tolerance_ns)
    src, dst = _subset(keyframes, ri), _subset(cameras, ti)
    n = len(ri)
    note = ''
    if n >= 3:
        sv = np.linalg.svd(src.centres - src.centres.mean(axis=0), compute_uv=False)
        spread_floor = 1e-9 * (1.0 + float(np.max(np.abs(src.centres))))
        if sv[0] > spread_floor and sv[1] >= COLLINEAR_RATIO * sv[0]:
            sim = umeyama(src.centres, dst.centres)
            s, rot, t = sim.scale, sim.rotation, sim.translation
            ce, oe = _residuals(s, rot, t, src, dst)
            return Alignment('umeyama', s, rot, t, len(keyframes.stamps_ns), n, ce, oe)
        if sv[0] > spread_floor:
            s, rot, t = _with_orientations(src, dst)
            ce, oe = _residuals(s, rot, t, src, dst)
            note = 'keyframe centres are collinear: rotation taken from the camera orientations'
            return Alignment(
                'centres+orientations', s, rot, t, len(keyframes.stamps_ns), n, ce, oe, note
            )
        note = f'the {n} matched keyframes share one centre'
    else:
        note = (
            f'{n} of {len(keyframes.stamps_ns)} keyframes match a true camera stamp within '
            f'{tolerance_ns / 1e6:g} ms (3 needed to align)'
        )
    if result_frame != truth_frame:
        raise EvaluationError(
            f'cannot align the result to the truth: {note}, and the result frame '
            f'"{result_frame}" differs from the truth frame "{truth_frame}"'
        )
    rot, t = np.eye(3), np.zeros(3)
    ce, oe = _residuals(1.0, rot, t, src, dst)
    note += f'; compared in the common frame "{truth_frame}" without alignment'
    return Alignment('identity', 1.0, rot, t, len(keyframes.stamps_ns), n, ce, oe, note)
