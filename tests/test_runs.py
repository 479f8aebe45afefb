"""A folder holds one run of one input and parameter set: claims, locks, states, fingerprints."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from stockpile_ros.errors import StockpileError
from stockpile_ros.runs import claim, fingerprint_input, fingerprint_values, read_run


def _input(path: Path, text: str = 'frames') -> Path:
    path.mkdir(parents=True, exist_ok=True)
    (path / 'a.mcap').write_text(text)
    return path


def _refused(match: str, folder: Path, source: Path | None, values: dict[str, int],
             **flags: bool) -> None:  # fmt: skip
    with pytest.raises(StockpileError, match=match), claim(folder, source, values, **flags):
        pass


def test_fingerprints_follow_the_content_not_the_place(tmp_path: Path) -> None:
    one = fingerprint_input(_input(tmp_path / 'one'))
    assert fingerprint_input(_input(tmp_path / 'copy')) == one
    assert fingerprint_input(_input(tmp_path / 'other', 'framez')) != one
    assert fingerprint_values({'a': 1, 'work_dir': '/x'}) == fingerprint_values({'a': 1})
    assert fingerprint_values({'a': 1}) != fingerprint_values({'a': 2})


def test_states_of_a_run(tmp_path: Path) -> None:
    source, out = _input(tmp_path / 'in'), tmp_path / 'out'
    with claim(out, source, {'a': 1}) as run:
        assert read_run(out) is not None and read_run(out).state == 'running'  # type: ignore[union-attr]
    assert run.state == 'complete' and read_run(out).finished  # type: ignore[union-attr]
    with pytest.raises(KeyboardInterrupt), claim(out, source, {'a': 1}, resume=True):
        raise KeyboardInterrupt
    assert json.loads((out / 'run.json').read_text())['state'] == 'interrupted'
    with pytest.raises(RuntimeError), claim(out, source, {'a': 1}, resume=True):
        raise RuntimeError('stage broke')
    assert read_run(out).state == 'failed'  # type: ignore[union-attr]
    with claim(out, source, {'a': 1}, resume=True) as run:
        run.state = 'failed'  # a run that ended without a result says so itself
    assert read_run(out).state == 'failed'  # type: ignore[union-attr]


def test_a_second_run_at_once_is_refused(tmp_path: Path) -> None:
    source, out = _input(tmp_path / 'in'), tmp_path / 'out'
    with claim(out, source, {}):
        _refused('in use', out, source, {}, resume=True)


def test_refusals_name_the_cause(tmp_path: Path) -> None:
    source, out = _input(tmp_path / 'in'), tmp_path / 'out'
    with claim(out, source, {'a': 1}):
        (out / 'work').mkdir()
    _refused('--resume continues it', out, source, {'a': 1})
    _refused('another input', out, _input(tmp_path / 'b', 'other'), {'a': 1}, resume=True)
    _refused('other parameters', out, source, {'a': 2}, resume=True)
    with claim(out, _input(tmp_path / 'b', 'other'), {'a': 1}, fresh=True):
        assert not (out / 'work').exists()
    stray = tmp_path / 'stray'
    stray.mkdir()
    (stray / 'report.json').write_text('{}')
    _refused('holds no run record', stray, source, {})
    _refused('no run to rerun', tmp_path / 'empty', None, {})
    with claim(out, None, {'a': 5}) as rerun:  # a stage rerun keeps the input, takes new values
        assert rerun.input == str(tmp_path / 'b')
