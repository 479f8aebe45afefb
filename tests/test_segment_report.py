from __future__ import annotations

import json
import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from segment_fixtures import make_report, small_pile, small_pile_file

from stockpile_ros.artefacts import KeyframePose, MeshInfo, ScaleRecord, from_json, load
from stockpile_ros.cli import main
from stockpile_ros.meshio import LabelledMesh, read_labelled_mesh, write_labelled_mesh
from stockpile_ros.result import Report
from stockpile_ros.ros import messages as m
from stockpile_ros.ros import topics
from stockpile_ros.ros.publications import capture_warnings
from stockpile_ros.ros.typestore import typestore
from stockpile_ros.segment.measure import RockMeasure, visibility_warnings
from stockpile_ros.segment.pipeline import analyse_mesh


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
    # JSON has no NaN: an undefined number is written as null.
    json.loads((out / 'report.json').read_text(), parse_constant=lambda c: 1 / 0)
    report = load(Report, out / 'report.json')
    assert report.schema == 'stockpile-report/3'
    assert report.units == 'm' and report.frame_id == 'stockpile'
    # The scale and the keyframes come from mesh.json, the scale's parts and note filled in.
    assert report.scale == ScaleRecord('target', 0.5, 0.01)
    assert report.keyframes == [KeyframePose(5, [1, 2, 3], [0, 0, 0, 1])]
    assert len(report.rocks) >= 3
    for rock in report.rocks:
        assert rock.a >= rock.b >= rock.c > 0
        assert 0 <= rock.confidence <= 1 and 0 < rock.visible_fraction <= 1
    spec = report.gradation.spec
    assert spec.class_name == 'I' and spec.checked
    assert spec.verdict in ('PASS', 'FAIL', 'UNDECIDED')
    assert spec.passed == {'PASS': True, 'FAIL': False}.get(spec.verdict)
    assert [row.key for row in spec.limits] == ['d15', 'd50', 'd85', 'd100']
    assert 'NCHRP Report 568' in spec.standard and 'check the limits' in spec.caveat
    for key in ('d15', 'd50', 'd85'):
        lo, hi = report.gradation.intervals.mass[key]
        value = report.gradation.characteristic[key]
        assert value is None or lo is None or lo <= value <= hi
    prov = report.provenance
    assert prov is not None
    assert prov.input_path == str(mesh_path) and len(prov.input_sha256) == 64
    assert prov.parameters_changed == {'gradation.spec_class': 'I'}
    assert prov.keyframes_used == 1 and prov.scale.method == 'target'
    assert prov.created.endswith('+00:00') and prov.tool_version
    assert report.segmentation.mode == 'default'
    # The class checked asks for the smallest rock of interest: half class I's smallest D15. This
    # mesh is too coarse for it: the floor of min_rock_edges applies, and the result says so.
    scale = report.segmentation.scale
    assert scale.source == 'class' and scale.requested == pytest.approx(0.5 * 3.7 * 0.0254)
    assert scale.edge > 0
    floor = report.segmentation.min_rock_edges * scale.edge
    assert scale.min_rock_b == pytest.approx(max(scale.requested, floor))
    assert any('the mesh resolves' in w for w in report.warnings)
    # Its limits under the smallest rock resolved are left undecided whatever the values read.
    unresolved = [
        row
        for row in spec.limits
        if any(x is not None and x < scale.min_rock_b for x in (row.min, row.max))
    ]
    assert unresolved and spec.verdict == 'UNDECIDED'
    assert all(
        row.status == 'undecided' and 'this run resolves' in row.reason for row in unresolved
    )
    assert report.mesh.faces == len(f)
    assert report.mesh.check is not None and report.mesh.check.faces_kept == len(f)
    assert any('kf_00044_000145.png' in w for w in report.warnings)
    seg = read_labelled_mesh(out / 'segments.ply')
    assert len(seg.faces) == len(f)
    assert set(np.unique(seg.labels)) >= {r.id for r in report.rocks}
    rows = (out / 'rocks.csv').read_text().strip().splitlines()
    assert len(rows) == len(report.rocks) + 1
    html = (out / 'index.html').read_text()
    assert 'data:image/png;base64,' in html and 'Stockpile report' in html
    assert 'src="http' not in html and 'src="file' not in html
    assert spec.caveat[:40] in html and 'No keyframe photo' in html
    assert 'D50 by mass' in html and '[mm]' in html
    for name in ('gradation.png', 'render.png'):
        assert (out / name).read_bytes()[:4] == b'\x89PNG'
    assert (out / 'report.pdf').read_bytes()[:5] == b'%PDF-'
    assert rows[1].endswith(',m')


def test_orientation_is_the_measured_axes() -> None:
    v, f, _ = small_pile()
    analysis = analyse_mesh(v, f)
    labels = analysis.segmentation.labels
    for rock in analysis.report.rocks:
        rot = Rotation.from_quat(rock.orientation_xyzw).as_matrix()
        pts = v[np.unique(f[labels == rock.id])] - rock.centroid
        extent = np.ptp(pts @ rot, axis=0)
        # x along a, z along c: the visible surface is longest along x and shortest along z.
        assert extent[0] >= extent[1] >= extent[2] * 0.999
        assert np.linalg.det(rot) == pytest.approx(1.0)


def test_a_run_without_scale_shows_no_metres_and_no_verdict(tmp_path, capsys) -> None:
    mesh_path = small_pile_file(tmp_path)
    out = tmp_path / 'unscaled'
    assert main(['segment', str(mesh_path), '--out', str(out), '--spec-class', 'I']) == 0
    printed = capsys.readouterr().out
    assert 'model units' in printed and 'kg' not in printed and 'REFUSED' in printed
    report = load(Report, out / 'report.json')
    assert report.units == 'model' and report.scale.method == 'none'
    spec = report.gradation.spec
    assert spec.verdict == 'REFUSED' and spec.checked is False and spec.passed is None
    assert 'model units' in spec.reasons[0]
    assert all(rock.mass is None for rock in report.rocks)
    assert report.gradation.total_mass is None and report.gradation.sieves == []
    # Without scale the class does not set the smallest rock of interest either.
    assert report.segmentation.scale.source == 'mesh'
    rows = (out / 'rocks.csv').read_text().strip().splitlines()
    header = rows[0].split(',')
    first = dict(zip(header, rows[1].split(','), strict=True))
    assert first['units'] == 'model' and first['mass'] == ''
    html = (out / 'index.html').read_text()
    text = re.sub(r'<style.*?</style>|<[^>]+>', ' ', html, flags=re.S)
    assert 'model units' in text and 'REFUSED' in text
    for unit in (r'\bkg\b', r'\blb\b', r'\bmm\b', r'\[m\]', r'\d m\b', r'\bm per\b', r'\bm³'):
        assert not re.search(unit, text), unit


def test_cli_paper_mode_without_mesh_info(tmp_path) -> None:
    mesh_path = small_pile_file(tmp_path)
    out = tmp_path / 'paper'
    assert main(['segment', str(mesh_path), '--out', str(out), '--mode', 'paper']) == 0
    report = load(Report, out / 'report.json')
    assert report.scale.method == 'none'
    assert report.segmentation.threshold == 0.7
    assert report.gradation.spec.checked is False
    assert report.segmentation.scale.source == 'mesh'


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
    # Many: the first twelve, and the table for the rest.
    many = [replace(base, id=k, visible_fraction=0.3) for k in range(1, 31)]
    (long,) = visibility_warnings(many)
    assert '(ids 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12 and 18 more: rocks.csv, partly_seen)' in long
    report = make_report([], ScaleRecord())
    report.warnings = [text]
    ((topic, msg),) = capture_warnings(m.RosbagsFactory(typestore()), 0, report)
    assert topic == topics.DIAGNOSTICS
    assert msg.status[0].name == 'stockpile/capture' and msg.status[0].message == text


def test_a_keyframe_photo_gets_the_rocks_outlined(tmp_path) -> None:
    import cv2

    from stockpile_ros.segment.provenance import Provenance
    from stockpile_ros.segment.render import overview_camera
    from stockpile_ros.segment.report import write_result_folder

    v, f, _ = small_pile()
    cam = overview_camera(v, width=320, height=240, azimuth_deg=30.0)
    keyframes = tmp_path / 'work' / 'keyframes'
    keyframes.mkdir(parents=True)
    cv2.imwrite(str(keyframes / 'kf_1.png'), np.full((240, 320, 3), 40, dtype=np.uint8))
    entry = {'file': 'kf_1.png', 'stamp_ns': 7, 'camera': {'width': 320, 'height': 240,
             'k': cam.k.ravel().tolist(), 'd': [], 'distortion_model': 'plumb_bob'}}  # fmt: skip
    (keyframes / 'keyframes.jsonl').write_text(json.dumps(entry) + '\n')
    pose = {'stamp_ns': 7, 'position': cam.position.tolist(),
            'orientation_xyzw': Rotation.from_matrix(cam.rotation).as_quat().tolist()}  # fmt: skip
    info = from_json(MeshInfo, {'scale': {'method': 'target', 'rel_uncertainty': 0.01},
                                'units': 'm', 'keyframes': [pose]})  # fmt: skip
    analysis = analyse_mesh(v, f, mesh_info=info)
    out = tmp_path / 'result'
    paths = write_result_folder(out, analysis, Provenance(input_path='x'), None, keyframes)
    photo = cv2.imread(str(paths['keyframe.png']))
    assert photo is not None
    # Outlines (white for well-seen rocks, orange for partly seen ones) are drawn on the photo.
    bright = (photo.max(axis=2) > 200).sum()
    assert bright > 100
    html = (out / 'index.html').read_text()
    assert 'Keyframe kf_1.png' in html and 'No keyframe photo' not in html


def test_the_result_folder_is_replaced_whole_never_mixed(tmp_path, capsys) -> None:
    mesh_path = small_pile_file(tmp_path)
    out = tmp_path / 'result'
    argv = ['segment', str(mesh_path), '--out', str(out), '--units', 'm']
    assert main(argv) == 0
    (out / 'stale.txt').write_text('from an earlier run')
    assert main(argv) == 0  # a rerun replaces the folder: no file of the earlier run is left
    assert not (out / 'stale.txt').exists() and (out / 'report.json').is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.result')]
    other = tmp_path / 'notes'
    other.mkdir()
    (other / 'mine.txt').write_text('keep me')
    assert main(['segment', str(mesh_path), '--out', str(other), '--units', 'm']) == 2
    assert 'holds files but no result' in capsys.readouterr().err
    assert (other / 'mine.txt').read_text() == 'keep me'
