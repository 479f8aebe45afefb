"""Quality gates between reconstruction stages: a capture that would give a partial model stops.

The registration gate judges a Structure-from-Motion result by what any image set has, ordered
keyframes of a stream or unordered photos: how many images were given, which landed in which
model, and optionally where the cameras of the largest model are and where the pile is. It fails
when too small a share of the images lands in one model (the rest would be left out of the
surface, so rocks would be missing without a word), or when the cameras of that model see the pile
from too narrow a range of directions (its far sides are not there to measure).

The span is the widest angle between two registered cameras as seen from the pile centre (at most
180 degrees): about the arc swept for an arc or orbit up to a half circle, and
``2 atan(L / 2 d)`` for a straight pass of length ``L`` at distance ``d``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import numpy.typing as npt

from ..errors import CaptureError
from ..ranges import Range

__all__ = ['GateOptions', 'GateReport', 'angular_span', 'registration_gate']

F64 = npt.NDArray[np.float64]

_NAMES_SHOWN = 6


@dataclass(frozen=True)
class GateOptions:
    """Bounds of :func:`registration_gate`.

    Attributes:
        min_registered_share: Fewest of the images, as a share, that must land in the largest
            model. On the simulated paths of ``bench/bench_keyframes.py`` good captures
            registered every keyframe; the 120-rock orbit whose keyframes were 35 degrees apart
            registered 2 of 10.
        min_span_deg: Narrowest span [deg] of the largest model's cameras around the pile
            centre (see the module documentation; 0 disables). 30 degrees is a short pass: 1.6 m
            long at 3 m from the pile.

    """

    min_registered_share: Annotated[float, Range(0.0, 1.0)] = 0.8
    min_span_deg: Annotated[float, Range(0.0, 180.0)] = 30.0


@dataclass
class GateReport:
    """The gate's measurements and verdict.

    Attributes:
        passed: Whether the model may be used.
        images: Images given.
        models: Names of the images registered in each model, largest model first.
        unregistered: Images in no model.
        share: Share of the images in the largest model.
        span_deg: Span of the largest model's cameras around the pile centre [deg], None when
            no camera centres were given.
        reason: What failed, measured ('' when passed).
        advice: What to do about it ('' when passed).
        noun: What the images are called in the texts (``"keyframes"``, ``"photos"``).

    """

    passed: bool
    images: int
    models: list[list[str]]
    unregistered: list[str]
    share: float
    span_deg: float | None
    reason: str = ''
    advice: str = ''
    noun: str = 'keyframes'

    def as_dict(self) -> dict[str, Any]:
        """JSON form (as in ``sparse.json``)."""
        return {
            'passed': self.passed,
            'images': self.images,
            'registered': len(self.models[0]) if self.models else 0,
            'share': self.share,
            'span_deg': self.span_deg,
            'models': self.models,
            'unregistered': self.unregistered,
            'reason': self.reason,
            'advice': self.advice,
        }

    def check(self, stage: str) -> None:
        """Raise the failure as a :class:`CaptureError` of ``stage``; nothing when passed."""
        if not self.passed:
            raise CaptureError(stage, self.reason, self.advice)


def angular_span(centres: F64, pile_centre: F64) -> float:
    """Widest angle [deg] between two of ``centres`` (Nx3) as seen from ``pile_centre``."""
    rays = np.asarray(centres, dtype=np.float64).reshape(-1, 3) - np.asarray(pile_centre)
    lengths = np.linalg.norm(rays, axis=1)
    rays = rays[lengths > 0] / lengths[lengths > 0, None]
    if len(rays) < 2:
        return 0.0
    return float(np.degrees(np.arccos(np.clip((rays @ rays.T).min(), -1.0, 1.0))))


def _names(names: Sequence[str]) -> str:
    """Return a few names, then how many more."""
    shown = ', '.join(names[:_NAMES_SHOWN])
    more = len(names) - _NAMES_SHOWN
    return shown + (f' and {more} more' if more > 0 else '')


def registration_gate(
    names: Sequence[str],
    models: Sequence[Sequence[str]],
    options: GateOptions | None = None,
    *,
    centres: Mapping[str, Sequence[float] | F64] | None = None,
    pile_centre: Sequence[float] | F64 | None = None,
    noun: str = 'keyframes',
) -> GateReport:
    """Judge a Structure-from-Motion result.

    Args:
        names: Every image given to Structure-from-Motion.
        models: The names registered in each model it produced (any order).
        options: The bounds.
        centres: Camera centres of the largest model's images by name (model coordinates);
            with ``pile_centre``, the span is measured.
        pile_centre: The pile's centre in the same coordinates.
        noun: What the images are called in the texts.

    Returns:
        The report; :meth:`GateReport.check` raises its failure.

    """
    opt = options or GateOptions()
    ordered = sorted((sorted(m) for m in models if m), key=len, reverse=True)
    registered = {n for m in ordered for n in m}
    unregistered = [n for n in names if n not in registered]
    total = len(names)
    largest = len(ordered[0]) if ordered else 0
    share = largest / total if total else 0.0
    span = None
    if centres is not None and pile_centre is not None and ordered:
        points = [centres[n] for n in ordered[0] if n in centres]
        span = angular_span(np.asarray(points, dtype=np.float64), np.asarray(pile_centre))
    failures = []
    advice = []
    if share < opt.min_registered_share:
        sizes = ', '.join(str(len(m)) for m in ordered) or 'none'
        where = '; '.join(f'model {i + 1}: {_names(m)}' for i, m in enumerate(ordered))
        lost = f'; in no model: {_names(unregistered)}' if unregistered else ''
        failures.append(
            f'{largest} of {total} {noun} registered in one model ({100 * share:.0f} %, at least '
            f'{100 * opt.min_registered_share:.0f} % needed), in {len(ordered)} model'
            f'{"" if len(ordered) == 1 else "s"} ({sizes}): {where}{lost}'
        )
        advice.append(
            f'Capture again with more overlap between the {noun} (move more slowly, keep the '
            'pile in view, turn less between views); split models mean a stretch the views did '
            'not link'
        )
    if span is not None and opt.min_span_deg > 0 and span < opt.min_span_deg:
        failures.append(
            f'the {largest} registered {noun} see the pile from directions at most '
            f'{span:.0f} degrees apart (at least {opt.min_span_deg:.0f} needed)'
        )
        advice.append('Move further along or around the pile so that it is seen from more sides')
    return GateReport(
        passed=not failures,
        images=total,
        models=ordered,
        unregistered=unregistered,
        share=share,
        span_deg=span,
        reason='; '.join(failures),
        advice='. '.join(advice),
        noun=noun,
    )
