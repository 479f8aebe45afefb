"""Score a segmentation against true labels on the same mesh (the yardstick of bench/).

Where the true rock under every face is known (a simulated surface meshed directly, see
:mod:`stockpile_ros.tools.sim.bed`), no transfer between surfaces is needed: each face's true
label is given, and the matching is the one ``stockpile evaluate`` uses (``match_rocks``: one to
one, surface IoU at least ``min_iou``), with each face a piece of its own. The figures are those of
``evaluate``'s visible detection and sizes: true rocks under ``visible_threshold`` are neither
missed when undetected nor counted against precision when found, whole or in pieces
(``RockMatching.on_hidden``). The true D50 is, as in ``evaluate`` (``truth.json``'s gradation),
that of every true rock, the reported one that of every reported rock; the D50 of the visible
true rocks is given beside it.

Where the smallest rock of interest lies above a bed's smallest rocks (``min_b``: a gravel bar's
fines under what its mesh resolves), the rocks under it are treated as the barely visible ones
are: neither missed nor, found alone, counted either way. A reported rock made of several of
them is a false rock, and is counted apart (``clusters``).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ...segment.gradation import gradation
from .match import LabelTransfer, MatchOptions, match_rocks

__all__ = ['OUTCOMES', 'LabelScore', 'SizedRock', 'label_outcomes', 'score_labels']

#: What became of a true rock in a labelling, as :func:`label_outcomes` counts it.
OUTCOMES = ('matched', 'with another rock', 'in pieces', 'short')


@dataclass(frozen=True)
class SizedRock:
    """A rock's size and mass, true or measured.

    Attributes:
        b: Intermediate dimension [m].
        mass: Mass [kg].
        visible_fraction: Share of the rock's surface seen (truth only; 1 for measured rocks).

    """

    b: float
    mass: float
    visible_fraction: float = 1.0


@dataclass(frozen=True)
class LabelScore:
    """Detection and size figures of one segmentation.

    Attributes:
        visible: True rocks at least ``visible_threshold`` visible.
        reported: Measured rocks.
        found: Visible true rocks matched one to one.
        recall: ``found / visible``.
        precision: ``found`` over the reported rocks not about a less visible rock.
        merges: Reported rocks holding most of two or more true rocks.
        clusters: Reported rocks not about one true rock that lie mostly (``major_share`` of
            their area) on true rocks under ``min_b``: several small rocks taken for one.
        splits: True rocks cut into two or more reported rocks.
        b_error: Median of ``|b / b_true - 1|`` over the found rocks.
        b_bias: Median of ``b / b_true - 1`` over the found rocks.
        d50_true: D50 by mass (of b) of every true rock [m].
        d50: D50 by mass of the reported rocks [m].
        d50_error: ``d50 / d50_true - 1``.
        d50_true_visible: D50 by mass of the visible true rocks [m].
        d50_error_visible: ``d50 / d50_true_visible - 1``: the reported rocks include the
            barely visible ones found, so this is not like for like.
        pairs: Every one-to-one match as (reported id, true id), barely visible rocks' too.

    """

    visible: int
    reported: int
    found: int
    recall: float
    precision: float
    merges: int
    clusters: int
    splits: int
    b_error: float
    b_bias: float
    d50_true: float
    d50: float
    d50_error: float
    d50_true_visible: float
    d50_error_visible: float
    pairs: tuple[tuple[int, int], ...]


def _d50(rocks: list[SizedRock]) -> float:
    d = gradation([r.b for r in rocks], [r.mass for r in rocks]).d50
    return float(d) if d is not None else float('nan')


def score_labels(
    true_labels: npt.ArrayLike,
    labels: npt.ArrayLike,
    areas: npt.ArrayLike,
    truth: Mapping[int, SizedRock],
    measured: Mapping[int, SizedRock],
    options: MatchOptions | None = None,
    min_b: float = 0.0,
) -> LabelScore:
    """Match the measured rocks to the true ones on shared faces and score them.

    Args:
        true_labels: Per face, the true rock id (0: ground).
        labels: Per face, the segment id (0: none); only ids in ``measured`` are rocks.
        areas: Per face, its area.
        truth: Every true rock by id.
        measured: The reported rocks by segment id.
        options: Matching thresholds (``evaluate``'s defaults when None).
        min_b: The smallest rock of interest [m]: true rocks under it count as barely visible
            ones do, and reported rocks made of several of them as ``clusters``.

    """
    opt = options or MatchOptions()
    t = np.asarray(true_labels, dtype=np.int64)
    a = np.asarray(areas, dtype=np.float64)
    transfer = LabelTransfer(np.arange(len(t)), t, np.zeros(len(t)), a)
    result_ids, true_ids = sorted(measured), sorted(truth)
    matching = match_rocks(labels, transfer, result_ids, true_ids, opt)
    visible = {
        k for k, r in truth.items() if r.visible_fraction >= opt.visible_threshold and r.b >= min_b
    }
    fines = [k for k, r in truth.items() if r.b < min_b]
    hits = matching.detection(visible, fines, opt.major_share)
    found = hits.found
    rel = np.array([measured[r].b / truth[k].b - 1.0 for r, k in found])
    d50_true = _d50(list(truth.values()))
    d50_visible = _d50([truth[k] for k in visible])
    d50 = _d50(list(measured.values()))
    return LabelScore(
        visible=len(visible),
        reported=len(measured),
        found=len(found),
        recall=hits.recall if hits.recall is not None else float('nan'),
        precision=hits.precision if hits.precision is not None else float('nan'),
        merges=len(matching.merges),
        clusters=len(hits.clusters),
        splits=len(matching.splits),
        b_error=float(np.median(np.abs(rel))) if len(rel) else float('nan'),
        b_bias=float(np.median(rel)) if len(rel) else float('nan'),
        d50_true=d50_true,
        d50=d50,
        d50_error=d50 / d50_true - 1.0,
        d50_true_visible=d50_visible,
        d50_error_visible=d50 / d50_visible - 1.0,
        pairs=tuple((r, k) for r, k, _ in matching.pairs),
    )


def label_outcomes(
    true_labels: npt.ArrayLike,
    labels: npt.ArrayLike,
    areas: npt.ArrayLike,
    rocks: Collection[int],
    min_iou: float = 0.5,
    foreign_share: float = 0.3,
) -> dict[str, int]:
    """Count what became of each of ``rocks`` in a labelling, by its best region alone.

    Meant for the labels between the steps of a segmentation, where no region is a reported
    rock yet: each rock is looked at through the region (label > 0) holding most of its
    surface, not matched one to one. ``matched``: that region's surface IoU with the rock is at
    least ``min_iou``; else ``with another rock``: more than ``foreign_share`` of the region is
    other surface (another rock's or ground); else ``in pieces``: the region holds under half the
    rock; else ``short``: the rest of the rock is unlabelled. A rock no region touches counts as
    ``in pieces``.

    Args:
        true_labels: Per face, the true rock id (0: ground).
        labels: Per face, the region id (0: none).
        areas: Per face, its area.
        rocks: The true rock ids to look at (the visible ones, say).
        min_iou: Least surface IoU of a match.
        foreign_share: Share of a region's area on other surface that makes it a region of two.

    Returns:
        The count of each of ``OUTCOMES``.

    """
    t = np.asarray(true_labels, dtype=np.int64)
    r = np.asarray(labels, dtype=np.int64)
    a = np.asarray(areas, dtype=np.float64)
    shared = np.zeros((int(t.max(initial=0)) + 1, int(r.max(initial=0)) + 1))
    np.add.at(shared, (t, r), a)
    rock_area, region_area = shared.sum(axis=1), shared.sum(axis=0)
    counts = dict.fromkeys(OUTCOMES, 0)
    for k in rocks:
        if k >= len(shared) or not shared[k, 1:].any():
            counts['in pieces'] += 1
            continue
        j = 1 + int(np.argmax(shared[k, 1:]))
        both = shared[k, j]
        if both >= min_iou * (rock_area[k] + region_area[j] - both):
            counts['matched'] += 1
        elif region_area[j] - both > foreign_share * region_area[j]:
            counts['with another rock'] += 1
        elif both < 0.5 * rock_area[k]:
            counts['in pieces'] += 1
        else:
            counts['short'] += 1
    return counts
