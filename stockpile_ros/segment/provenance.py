"""Where a result came from: the provenance block of report.json and of the page.

A QA record has to name its input, so the input is fingerprinted, cheaply: a file by the sha256 of
its bytes; a folder (a rosbag2 bag) by the sha256 of its ``metadata.yaml`` followed by the name
and size of every file in it, in sorted order, so a multi-gigabyte bag is identified without
reading its messages (a bag rewritten to the same sizes with other content would not be told
apart; its metadata.yaml, which holds message counts and time stamps, normally is).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .. import __version__

__all__ = ['Provenance', 'changed_parameters', 'fingerprint']

_CHUNK = 1 << 20


def fingerprint(path: str | Path) -> tuple[str, str]:
    """Return ``(sha256 hex, how it was computed)`` for an input file or bag folder.

    Raises:
        OSError: The path cannot be read.

    """
    target = Path(path)
    digest = hashlib.sha256()
    if target.is_dir():
        meta = target / 'metadata.yaml'
        if meta.is_file():
            digest.update(meta.read_bytes())
        for item in sorted(p for p in target.rglob('*') if p.is_file()):
            digest.update(
                f'{item.relative_to(target).as_posix()}\0{item.stat().st_size}\n'.encode()
            )
        how = 'sha256 of metadata.yaml, then the relative path and size of every file (sorted)'
        return digest.hexdigest(), how
    with target.open('rb') as data:
        for chunk in iter(lambda: data.read(_CHUNK), b''):
            digest.update(chunk)
    return digest.hexdigest(), 'sha256 of the file'


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
