"""`--params`, `--set` and the alias flags of reconstruct, segment and replay: checked on load."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from segment_fixtures import small_pile

from stockpile_ros.artefacts import load
from stockpile_ros.cli import main
from stockpile_ros.meshio import LabelledMesh, write_labelled_mesh
from stockpile_ros.result import Report
from stockpile_ros.settings import load_params_yaml


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], *reason: str) -> None:
    """Exit 2 with one line on stderr that names every part of ``reason``, and no traceback."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert 'Traceback' not in err
    for part in reason:
        assert part in err, err


@pytest.mark.parametrize(
    ('args', 'reason'),
    [
        (['--set', 'segment.threshold=.nan'], ('segment.threshold', 'nan', 'not a finite number')),
        (['--set', 'measure.specific_gravity=nan'], ('measure.specific_gravity', 'finite')),
        (['--threshold', 'inf'], ('--threshold', 'segment.threshold', 'inf')),
        (['--mode', 'fast'], ('--mode', "'fast' is not one of paper, default")),
        (['--spec-class', 'XI'], ('gradation.spec_class', "'XI'")),
        (['--set', 'measure.completion=guess'], ('measure.completion', 'auto, mirror')),
        (['--set', 'segment.treshold=0.9'], ("unknown parameter 'segment.treshold'", 'threshold')),
        (['--mode', 'paper', '--set', 'segment.mode=default'], ('--mode and --set', 'give one')),
    ],
)
def test_segment_refuses_bad_parameters_before_reading_the_mesh(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], reason: tuple[str, ...]
) -> None:
    # The mesh does not exist: a parameter refusal proves the check came first.
    argv = ['segment', str(tmp_path / 'missing.ply'), '--out', str(tmp_path / 'r'), *args]
    _refused(capsys, argv, *reason)
    assert not (tmp_path / 'r').exists()


@pytest.mark.parametrize(
    ('args', 'reason'),
    [
        (['--set', 'sfm.matcher=bogus'], ('sfm.matcher', "'bogus'", 'sequential, exhaustive')),
        (['--matcher', 'bogus'], ('--matcher', 'sfm.matcher', 'sequential, exhaustive')),
        (['--target', 'charuco:1x1:0.08:0.06'], ('--target', 'recon.target', '2 x 2 squares')),
        (['--set', 'selector.blur_ratio=.nan'], ('selector.blur_ratio', 'finite')),
        (['--set', 'dense.work_width=wide'], ('dense.work_width', 'expected int')),
    ],
)
def test_reconstruct_refuses_bad_parameters_before_any_stage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], reason: tuple[str, ...]
) -> None:
    work = tmp_path / 'work'
    _refused(capsys, ['reconstruct', str(tmp_path / 'no.mcap'), '--work', str(work), *args],
             *reason)  # fmt: skip
    assert not work.exists()


def test_replay_refuses_a_bad_parameter_before_opening_the_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ['replay', str(tmp_path / 'no.mcap'), '--out', str(tmp_path / 'o'),
            '--set', 'measure.specific_gravity=.nan']  # fmt: skip
    _refused(capsys, argv, 'measure.specific_gravity', 'finite')
    assert not (tmp_path / 'o').exists()


def test_a_bad_value_in_a_params_file_names_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    params = tmp_path / 'p.yaml'
    params.write_text('stockpile_reconstruction:\n  ros__parameters:\n    sfm:\n'
                      '      mapper: quick\n')  # fmt: skip
    argv = ['reconstruct', '--work', str(tmp_path / 'w'), '--params', str(params)]
    _refused(capsys, argv, str(params), 'sfm.mapper', "'quick'", 'incremental, global')


def test_reconstruct_writes_the_effective_parameters_before_the_stages(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    params = tmp_path / 'p.yaml'
    params.write_text(
        '/**:\n  ros__parameters:\n    sfm:\n      overlap: 3\n      max_features: 99\n'
    )
    work, photos = tmp_path / 'work', tmp_path / 'photos'
    photos.mkdir()
    # A folder without photos fails in the keyframe stage; the parameters it was given are on
    # record, and so is the failed run.
    argv = ['reconstruct', str(photos), '--work', str(work), '--params', str(params),
            '--set', 'sfm.overlap=5', '--no-odometry', '--matcher', 'exhaustive']  # fmt: skip
    assert main(argv) == 2
    assert str(photos) in capsys.readouterr().err
    assert json.loads((work / 'run.json').read_text())['state'] == 'failed'
    values = load_params_yaml(work / 'params.yaml')
    assert values['sfm.overlap'] == 5 and values['sfm.max_features'] == 99
    assert values['recon.use_odometry'] is False and values['sfm.matcher'] == 'exhaustive'
    assert values['work_dir'] == str(work) and values['dense.work_width'] == 1280


def test_segment_uses_the_table_and_records_it_in_the_result_folder(tmp_path: Path) -> None:
    v, f, _ = small_pile()
    mesh = tmp_path / 'mesh.ply'
    write_labelled_mesh(mesh, LabelledMesh(v, f, np.zeros(len(f), dtype=np.int32)))
    out = tmp_path / 'result'
    # The explicit threshold equals the table default, and still wins over the paper preset.
    argv = ['segment', str(mesh), '--out', str(out), '--mode', 'paper', '--threshold', '0.93',
            '--set', 'measure.specific_gravity=3.0']  # fmt: skip
    assert main(argv) == 0
    report = load(Report, out / 'report.json')
    assert report.segmentation.threshold == 0.93 and report.segmentation.mode == 'paper'
    assert report.segmentation.measure.specific_gravity == 3.0
    values = load_params_yaml(out / 'params.yaml')
    assert values['segment.threshold'] == 0.93 and values['segment.exclude_ground'] is False
    assert values['measure.specific_gravity'] == 3.0
    text = (out / 'params.yaml').read_text()
    assert '      threshold: 0.93  # set explicitly' in text
    assert '      exclude_ground: false\n' in text
