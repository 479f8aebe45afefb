"""Agreement of a segmentation with known per-face labels (used by tests and benchmarks)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ['rock_recall_precision']


def rock_recall_precision(
    truth: npt.NDArray[np.int32],
    predicted: npt.NDArray[np.int32],
    weights: npt.NDArray[np.float64] | None = None,
) -> tuple[float, float, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Mean per-rock recall and precision against the best-overlapping predicted segment.

    For every true rock (label > 0) the predicted segment (label > 0) sharing the most faces (or
    face area with ``weights``) is its match; recall is the overlap over the rock, precision the
    overlap over the segment. A rock no segment touches scores 0 / 0.

    Returns:
        Mean recall, mean precision, and the per-rock arrays (ordered by true label).

    """
    w = np.ones(len(truth)) if weights is None else np.asarray(weights, dtype=np.float64)
    rocks = np.unique(truth[truth > 0])
    both = (truth > 0) & (predicted > 0)
    n_pred = int(predicted.max()) + 1 if len(predicted) else 1
    pred_size = np.bincount(predicted, weights=w, minlength=n_pred)
    key = truth[both].astype(np.int64) * n_pred + predicted[both]
    uniq, inv = np.unique(key, return_inverse=True)
    overlap = np.bincount(inv.ravel(), weights=w[both])
    t_of, p_of = uniq // n_pred, uniq % n_pred
    recall = np.zeros(len(rocks))
    precision = np.zeros(len(rocks))
    for k, rock in enumerate(rocks):
        sel = np.flatnonzero(t_of == rock)
        if len(sel) == 0:
            continue
        best = sel[np.argmax(overlap[sel])]
        recall[k] = overlap[best] / w[truth == rock].sum()
        precision[k] = overlap[best] / pred_size[p_of[best]]
    if len(rocks) == 0:
        return 0.0, 0.0, recall, precision
    return float(recall.mean()), float(precision.mean()), recall, precision
