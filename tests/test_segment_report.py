from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from segment_fixtures import small_pile

from stockpile_ros import messages as m
from stockpile_ros import topics
from stockpile_ros.cli import main
from stockpile_ros.meshio import LabelledMesh, read_labelled_mesh, write_labelled_mesh
from stockpile_ros.msgs import typestore
from stockpile_ros.publish import capture_warnings
from stockpile_ros.segment.measure import RockMeasure, visibility_warnings

ROCK_KEYS = {'id', 'centroid', 'a', 'b', 'c', 'esd', 'volume', 'mass', 'visible_area',
             'visible_fraction', 'fer', 'sphericity', 'confidence'}  # fmt: skip
GRAD_KEYS = {'size_measure', 'sizes', 'percent_passing_count', 'percent_passing_mass', 'd10',
             'd15', 'd30', 'd50', 'd60', 'd85', 'd100', 'cu', 'cc', 'rock_count', 'total_mass',
             'spec'}  # fmt: skip


def test_cli_writes_a_valid_result_folder(tmp_path, capsys) -> None:
    v, f, _ = small_pile()
    mesh_path = tmp_path / 'mesh.ply'
    write_labelled_mesh(mesh_path, LabelledMesh(v, f, np.zeros(len(f), dtype=np.int32)))
    info = {'schema': 'stockpile-mesh/1', 'frame_id': 'stockpile', 'units': 'm',
            'scale': {'method': 'target', 'metres_per_unit': 0.5, 'rel_uncertainty': 0.01},
            'keyframes': [{'stamp_ns': 5, 'position': [1, 2, 3],
                           'orientation_xyzw': [0, 0, 0, 1]}],
            'keyframes_off_path': ['kf_00044_000145.png']}  # fmt: skip
    (tmp_path / 'mesh.json').write_text(json.dumps(info))
    out = tmp_path / 'result'
    status = main([
        'segment', str(mesh_path), '--out', str(out), '--mesh-info', str(tmp_path / 'mesh.json'),
        '--spec-class', 'I',
    ])  # fmt: skip
    assert status == 0
    assert 'rocks' in capsys.readouterr().out
    report = json.loads((out / 'report.json').read_text(), parse_constant=lambda c: 1 / 0)
    assert report['schema'] == 'stockpile-report/1'
    assert report['units'] == 'm' and report['frame_id'] == 'stockpile'
    assert report['scale'] == info['scale'] and report['keyframes'] == info['keyframes']
    assert len(report['rocks']) >= 3
    for rock in report['rocks']:
        assert set(rock) == ROCK_KEYS
        assert rock['a'] >= rock['b'] >= rock['c'] > 0
        assert 0 <= rock['confidence'] <= 1 and 0 < rock['visible_fraction'] <= 1
    assert set(report['gradation']) == GRAD_KEYS
    spec = report['gradation']['spec']
    assert spec['class'] == 'I' and spec['checked'] and isinstance(spec['passed'], bool)
    assert report['segmentation']['mode'] == 'default'
    # The class checked asks for the smallest rock of interest: half class I's smallest D15. This
    # mesh is too coarse for it: the floor of min_rock_edges applies, and the result says so.
    scale = report['segmentation']['scale']
    assert scale['source'] == 'class' and scale['requested'] == pytest.approx(0.5 * 3.7 * 0.0254)
    assert scale['edge'] > 0
    floor = report['segmentation']['min_rock_edges'] * scale['edge']
    assert scale['min_rock_b'] == pytest.approx(max(scale['requested'], floor))
    assert any('the mesh resolves' in w for w in report['warnings'])
    assert report['mesh']['faces'] == len(f)
    assert any('kf_00044_000145.png' in w for w in report['warnings'])
    seg = read_labelled_mesh(out / 'segments.ply')
    assert len(seg.faces) == len(f)
    assert set(np.unique(seg.labels)) >= {r['id'] for r in report['rocks']}
    rows = (out / 'rocks.csv').read_text().strip().splitlines()
    assert len(rows) == len(report['rocks']) + 1
    html = (out / 'index.html').read_text()
    assert 'data:image/png;base64,' in html and 'Stockpile report' in html
    for name in ('gradation.png', 'render.png'):
        assert (out / name).read_bytes()[:4] == b'\x89PNG'


def test_cli_paper_mode_without_mesh_info(tmp_path) -> None:
    v, f, _ = small_pile()
    mesh_path = tmp_path / 'mesh.ply'
    write_labelled_mesh(mesh_path, LabelledMesh(v, f, np.zeros(len(f), dtype=np.int32)))
    out = tmp_path / 'paper'
    assert main(['segment', str(mesh_path), '--out', str(out), '--mode', 'paper']) == 0
    report = json.loads((out / 'report.json').read_text())
    assert report['scale']['method'] == 'none'
    assert report['segmentation']['threshold'] == 0.7
    assert report['gradation']['spec']['checked'] is False
    assert report['segmentation']['scale']['source'] == 'mesh'


def test_cli_errors_are_messages(tmp_path, capsys) -> None:
    assert main(['segment', str(tmp_path / 'missing.ply'), '--out', str(tmp_path / 'o')]) == 2
    assert 'no such mesh' in capsys.readouterr().err


def test_partly_seen_rocks_raise_a_capture_warning() -> None:
    base = RockMeasure(id=1, centroid=(0.0, 0.0, 0.1), a=0.2, b=0.1, c=0.05, esd=0.1,
                       volume=1e-3, mass=2.65, visible_area=0.01, visible_fraction=0.6, fer=4.0,
                       sphericity=0.8, confidence=0.5, faces=100)  # fmt: skip
    rocks = [replace(base, id=k, visible_fraction=v) for k, v in enumerate((0.6, 0.7, 0.3, 0.8), 1)]
    # One rock in four seen on under 45 %: no warning.
    assert visibility_warnings(rocks) == []
    rocks.append(replace(base, id=5, visible_fraction=0.44))
    (text,) = visibility_warnings(rocks)
    assert text.startswith('2 of 5 rocks') and '(ids 3, 5)' in text
    ((topic, msg),) = capture_warnings(m.RosbagsFactory(typestore()), 0, {'warnings': [text]})
    assert topic == topics.DIAGNOSTICS
    assert msg.status[0].name == 'stockpile/capture' and msg.status[0].message == text
