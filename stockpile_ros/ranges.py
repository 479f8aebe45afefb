"""The range marker the option dataclasses put next to their number fields.

``overlap: Annotated[int, Range(1, 1000)] = 8`` declares the closed interval the parameter table
(:mod:`stockpile_ros.settings`) checks the value against; type checkers see a plain ``int``. The
table reads the marker back with ``typing.get_type_hints(cls, include_extras=True)``, so a field's
range, type, default and (in the class docstring) description are written in one place.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ['Range']


@dataclass(frozen=True)
class Range:
    """Closed interval a number parameter must lie in.

    Attributes:
        low: Smallest allowed value.
        high: Largest allowed value.

    """

    low: float
    high: float
