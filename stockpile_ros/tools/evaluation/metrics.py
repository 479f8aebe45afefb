"""Size errors of matched rocks, their summary statistics and the D50 error."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .align import Alignment
from .inputs import Rock

__all__ = ['QUANTITIES', 'RockErrors', 'relative_error', 'rock_errors', 'summarise']

# Compared per matched rock; lengths scale linearly, volume with the cube.
QUANTITIES = ('a', 'b', 'c', 'volume')
_POWER = {'a': 1, 'b': 1, 'c': 1, 'volume': 3}


@dataclass
class RockErrors:
    """Errors of one matched rock, in the truth's metric frame.

    Attributes:
        result_id: Result rock id.
        true_id: True rock id.
        iou: Surface intersection over union of the pair.
        visible_fraction: True visible fraction of the true rock.
        centroid_error: Distance between the aligned result centroid and the true one [m].
        true: True value per quantity.
        estimated: Result value per quantity, in truth metres (rescaled for unscaled results).
        relative: ``estimated / true - 1`` per quantity.
        absolute: ``estimated - true`` per quantity [m or m^3].

    """

    result_id: int
    true_id: int
    iou: float
    visible_fraction: float | None
    centroid_error: float | None
    true: dict[str, float | None]
    estimated: dict[str, float | None]
    relative: dict[str, float | None]
    absolute: dict[str, float | None]


def relative_error(estimated: float | None, true: float | None) -> float | None:
    """``estimated / true - 1``, None when either is missing or the truth is not positive."""
    if estimated is None or true is None or true <= 0:
        return None
    return estimated / true - 1.0


def _difference(estimated: float | None, true: float | None) -> float | None:
    return None if estimated is None or true is None else estimated - true


def rock_errors(
    pairs: list[tuple[int, int, float]],
    result_rocks: dict[int, Rock],
    true_rocks: dict[int, Rock],
    alignment: Alignment,
    length_factor: float,
) -> list[RockErrors]:
    """Errors of every matched pair, in true-id order.

    Args:
        pairs: (result id, true id, iou) of each match.
        result_rocks: Reported rocks by id.
        true_rocks: True rocks by id.
        alignment: Result-to-truth transform, for the centroids.
        length_factor: Truth metres per reported length unit: 1 for a result that claims metric
            units (its own scale is being judged), the alignment scale for an unscaled one.

    """
    out = []
    for rid, tid, iou in sorted(pairs, key=lambda p: p[1]):
        res, tru = result_rocks[rid], true_rocks[tid]
        true_vals = {q: getattr(tru, q) for q in QUANTITIES}
        est_vals: dict[str, float | None] = {}
        for q in QUANTITIES:
            value = getattr(res, q)
            est_vals[q] = None if value is None else value * length_factor ** _POWER[q]
        centroid_error = None
        if res.centroid is not None and tru.centroid is not None:
            aligned = alignment.apply(res.centroid.reshape(1, 3))[0]
            centroid_error = float(np.linalg.norm(aligned - tru.centroid))
        out.append(
            RockErrors(
                result_id=rid,
                true_id=tid,
                iou=iou,
                visible_fraction=tru.visible_fraction,
                centroid_error=centroid_error,
                true=true_vals,
                estimated=est_vals,
                relative={q: relative_error(est_vals[q], true_vals[q]) for q in QUANTITIES},
                absolute={q: _difference(est_vals[q], true_vals[q]) for q in QUANTITIES},
            )
        )
    return out


def summarise(errors: list[RockErrors]) -> dict[str, dict[str, float | int | None]]:
    """Per quantity: count, median and mean absolute % error, median and mean signed % error."""
    summary: dict[str, dict[str, float | int | None]] = {}
    for q in QUANTITIES:
        rel = np.array([e.relative[q] for e in errors if e.relative[q] is not None], dtype=float)
        pct = 100.0 * rel
        empty = len(pct) == 0
        summary[q] = {
            'n': len(pct),
            'median_abs_pct': None if empty else float(np.median(np.abs(pct))),
            'mean_abs_pct': None if empty else float(np.mean(np.abs(pct))),
            'median_pct': None if empty else float(np.median(pct)),
            'mean_pct': None if empty else float(np.mean(pct)),
        }
    return summary
