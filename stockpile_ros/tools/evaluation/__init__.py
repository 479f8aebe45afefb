"""Score a segmentation result against the simulator's ground truth (``stockpile evaluate``).

Reads only the result folder (``report.json`` + ``segments.ply``) and the truth folder
(``truth.json`` + ``scene.ply``), as ``docs/formats.md`` defines them.
"""

from __future__ import annotations

from .evaluate import SCHEMA, EvaluationOptions, evaluate, evaluate_sides
from .inputs import EvaluationError, load_result, load_truth
from .match import MatchOptions
from .table import format_table

__all__ = [
    'SCHEMA',
    'EvaluationError',
    'EvaluationOptions',
    'MatchOptions',
    'evaluate',
    'evaluate_sides',
    'format_table',
    'load_result',
    'load_truth',
]
