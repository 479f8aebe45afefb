"""Where a result came from: the provenance block of report.json and of the page.

A QA record has to name its input, so the input is fingerprinted, cheaply, as the run record
fingerprints it (:data:`stockpile_ros.runs.FINGERPRINT_METHOD`): a multi-gigabyte bag is
identified without reading all its messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .. import __version__
from ..runs import FINGERPRINT_METHOD, fingerprint_input

__all__ = ['Provenance', 'changed_parameters', 'fingerprint']


def fingerprint(path: str | Path) -> tuple[str, str]:
    """Return ``(sha256 hex, how it was computed)`` for an input file or bag folder.

    The same fingerprint as the run record's (:func:`stockpile_ros.runs.fingerprint_input`).

    Raises:
        OSError: The path cannot be read.

    """
    return fingerprint_input(Path(path)), FINGERPRINT_METHOD


def changed_parameters(
    values: Mapping[str, Any], default_values: Mapping[str, Any]
) -> dict[str, Any]:
    """Return the parameters whose effective value differs from its default, by name."""
    return {k: v for k, v in sorted(values.items()) if default_values.get(k, object()) != v}


@dataclass(frozen=True)
class Provenance:
    """What a result was made from and by whom, as the callers of the result writer know it.

    Attributes:
        site: Quarry or site name ('' when not given).
        pile: Name of the stockpile ('' when not given).
        operator: Who ran the measurement ('' when not given).
        input_path: The input the run was made from (bag, mesh file or folder).
        input_sha256: Fingerprint of the input, '' when it could not be read.
        fingerprint_method: How ``input_sha256`` was computed.
        parameters_changed: Every parameter whose effective value differs from its default.
        created: When the result was made, UTC, ISO 8601.
        tool_version: Version of stockpile_ros.

    """

    site: str = ''
    pile: str = ''
    operator: str = ''
    input_path: str = ''
    input_sha256: str = ''
    fingerprint_method: str = ''
    parameters_changed: dict[str, Any] = field(default_factory=dict)
    created: str = field(
        default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec='seconds')
    )
    tool_version: str = __version__

    @classmethod
    def for_input(
        cls,
        input_path: str | Path,
        values: Mapping[str, Any],
        default_values: Mapping[str, Any],
    ) -> Provenance:
        """Fill a provenance from the input path and the run's parameter values.

        ``report.site``, ``report.pile`` and ``report.operator`` come from ``values``; an input
        that cannot be read gets an empty fingerprint and the reason in ``fingerprint_method``.
        """
        try:
            digest, how = fingerprint(input_path)
        except OSError as exc:
            digest, how = '', f'not fingerprinted: {exc.strerror or exc}'
        return cls(
            site=str(values.get('report.site', '')),
            pile=str(values.get('report.pile', '')),
            operator=str(values.get('report.operator', '')),
            input_path=str(input_path),
            input_sha256=digest,
            fingerprint_method=how,
            parameters_changed=changed_parameters(values, default_values),
        )

    def as_dict(self) -> dict[str, Any]:
        """Return the ``provenance`` entry of report.json (without keyframes and scale)."""
        return asdict(self)
