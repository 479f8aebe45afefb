"""A folder belongs to one run at a time, of one input and one parameter set.

``stockpile replay`` and ``stockpile reconstruct`` claim their folder before anything is written:
``run.json`` records the input, its fingerprint, the parameters' fingerprint and the state
(``running``, ``complete``, ``failed`` or ``interrupted``), and a lock keeps a second run out
while the first is alive. A folder that holds another input's run is refused, never appended to;
continuing the same input is asked for (``--resume``), and so is starting over (``--fresh``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import fcntl
import hashlib
import json
import os
import shutil
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, Any, Literal

from .errors import StockpileError

__all__ = [
    'FINGERPRINT_METHOD',
    'RUN_FILE',
    'RunRecord',
    'claim',
    'fingerprint_input',
    'fingerprint_values',
    'read_run',
    'write_json_atomic',
]

RUN_FILE = 'run.json'
_LOCK_FILE = '.lock'
_SCHEMA = 'stockpile-run/1'
# What a fingerprint reads of each file: its size and its first and last MiB (a bag's chunks
# change throughout; its head holds the schema and the first messages, its tail the summary).
_SAMPLE = 1 << 20

FINGERPRINT_METHOD = 'sha256 over each file: its relative name, its size, its first and last MiB'
"""How :func:`fingerprint_input` identifies an input, in words (the report says it)."""

State = Literal['running', 'complete', 'failed', 'interrupted']


@dataclass
class RunRecord:
    """``run.json``: what a folder holds and how its last run ended.

    Attributes:
        input: The input as given (bag, photo folder, video).
        input_fingerprint: :func:`fingerprint_input` of it.
        params_fingerprint: :func:`fingerprint_values` of the effective parameters.
        state: ``running`` (or killed while running), ``complete``, ``failed``, ``interrupted``.
        started: UTC start, ISO 8601.
        finished: UTC end, ISO 8601; '' while running.
        pid: The process that ran it.
        schema: ``stockpile-run/1``.

    """

    input: str
    input_fingerprint: str
    params_fingerprint: str
    state: State
    started: str
    finished: str = ''
    pid: int = 0
    schema: str = _SCHEMA


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')


def _sample(path: Path, digest: Any) -> None:
    size = path.stat().st_size
    digest.update(f'{size}\0'.encode())
    with path.open('rb') as f:
        digest.update(f.read(_SAMPLE))
        if size > _SAMPLE:
            f.seek(max(_SAMPLE, size - _SAMPLE))
            digest.update(f.read(_SAMPLE))


def fingerprint_input(path: Path) -> str:
    """Return a sha256 over a file's or a folder's files (names, sizes, first and last MiB).

    Cheap on a recording of gigabytes and different for any other recording or photo set.
    """
    digest = hashlib.sha256()
    files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
    for file in files:
        digest.update(str(file.relative_to(path) if path.is_dir() else file.name).encode())
        _sample(file, digest)
    return digest.hexdigest()


def fingerprint_values(values: dict[str, Any]) -> str:
    """Return a sha256 of parameter values (the work folder left out: it is where, not what)."""
    kept = {k: v for k, v in sorted(values.items()) if k != 'work_dir'}
    return hashlib.sha256(json.dumps(kept, sort_keys=True, default=str).encode()).hexdigest()


def write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    """Write JSON beside ``path`` and rename it into place (never a half-written file)."""
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    tmp.write_text(json.dumps(data, indent=1) + '\n')
    tmp.replace(path)


def read_run(folder: Path) -> RunRecord | None:
    """Return the folder's ``run.json``, None when it has none.

    Raises:
        StockpileError: ``run.json`` is unreadable.

    """
    path = folder / RUN_FILE
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        return RunRecord(**data)
    except (OSError, ValueError, TypeError) as exc:
        raise StockpileError(f'{path}: unreadable run record ({exc})') from exc


@contextlib.contextmanager
def _lock(folder: Path) -> Iterator[IO[str]]:
    handle = (folder / _LOCK_FILE).open('a+')
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise StockpileError(
                f'{folder} is in use by another run; wait for it or choose another folder'
            ) from None
        yield handle
    finally:
        handle.close()


@contextlib.contextmanager
def claim(
    folder: Path,
    source: Path | None,
    values: dict[str, Any],
    *,
    resume: bool = False,
    fresh: bool = False,
) -> Iterator[RunRecord]:
    """Hold ``folder`` for one run of ``source`` with ``values``; record how the run ends.

    Args:
        folder: The work or output folder (created).
        source: The input; None reruns stages of the run the folder holds (``stockpile
            reconstruct --stage mesh``: other parameters are the point, the input is the same).
        values: The effective parameters.
        resume: Continue the run of the same input and parameters that the folder holds.
        fresh: Remove what the folder holds and start over.

    Yields:
        The record, state ``running``; written back ``complete`` when the block ends (unless
        the block set another state), ``interrupted`` on Ctrl-C and ``failed`` on any other
        exception (which goes on).

    Raises:
        StockpileError: The folder is a file or in use; it holds another input's or parameter
            set's run, or a run and neither ``resume`` nor ``fresh`` was given, or files but no
            run record; ``source`` is None and it holds no run.

    """
    if folder.exists() and not folder.is_dir():
        raise StockpileError(f'{folder} is a file, not a folder; choose another')
    folder.mkdir(parents=True, exist_ok=True)
    with _lock(folder):
        held = read_run(folder)
        if fresh:
            for path in folder.iterdir():
                if path.name != _LOCK_FILE:
                    shutil.rmtree(path) if path.is_dir() else path.unlink()
            held = None
        if source is None:
            if held is None:
                raise StockpileError(f'{folder} holds no run to rerun a stage of; run it whole')
            params = fingerprint_values(values)
            record = dataclasses.replace(held, state='running', started=_now(), finished='',
                                         pid=os.getpid(), params_fingerprint=params)  # fmt: skip
        else:
            record = RunRecord(str(source), fingerprint_input(source), fingerprint_values(values),
                               'running', _now(), pid=os.getpid())  # fmt: skip
            _check_held(folder, held, record, resume)
        write_json_atomic(folder / RUN_FILE, asdict(record))
        try:
            yield record
        except KeyboardInterrupt:
            record.state = 'interrupted'
            raise
        except BaseException:
            record.state = 'failed'
            raise
        else:
            if record.state == 'running':
                record.state = 'complete'
        finally:
            record.finished = _now()
            write_json_atomic(folder / RUN_FILE, asdict(record))


def _check_held(folder: Path, held: RunRecord | None, record: RunRecord, resume: bool) -> None:
    """Refuse a folder that another input's run, or an unasked-for continuation, would mix."""
    if held is None:
        if any(p.name != _LOCK_FILE for p in folder.iterdir()):
            raise StockpileError(
                f'{folder} is not empty and holds no run record; choose an empty folder, or '
                '--fresh to clear it'
            )
        return
    if held.input_fingerprint != record.input_fingerprint:
        raise StockpileError(
            f'{folder} holds a run of another input ({held.input}, {held.state}, '
            f'{held.started}); choose another folder, or --fresh to start over there'
        )
    if held.params_fingerprint != record.params_fingerprint:
        raise StockpileError(
            f'{folder} holds a run of this input with other parameters ({held.state}, '
            f'{held.started}); choose another folder, or --fresh to start over there'
        )
    if not resume:
        raise StockpileError(
            f'{folder} holds a run of this input ({held.state}, {held.started}); --resume '
            'continues it, --fresh starts over'
        )
