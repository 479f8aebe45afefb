"""Stage artefacts and the report: one JSON round trip each, schemas checked, bad fields refused."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from segment_fixtures import small_pile

from stockpile_ros.artefacts import (
    ArtefactError,
    DenseSummary,
    KeyframePose,
    KeyframeRecord,
    KeyframeSummary,
    MeshInfo,
    ModelImages,
    OdometryEntry,
    ScaleRecord,
    SimilarityRecord,
    SparseSummary,
    from_json,
    load,
    save,
    to_json,
)
from stockpile_ros.camera import CameraModel
from stockpile_ros.meshcheck import MeshCheck, check_mesh
from stockpile_ros.meshio import LabelledMesh
from stockpile_ros.result import (
    ClassDecision,
    GradationCurve,
    GradationRecord,
    Intervals,
    LimitRow,
    MeasureRecord,
    MeshRecord,
    ProvenanceRecord,
    ProvenanceScale,
    Report,
    RockRecord,
    RosinRammler,
    SegmentationRecord,
    Sieve,
)
from stockpile_ros.segment.gradation import load_class_table
from stockpile_ros.segment.measure import MeasureParams
from stockpile_ros.segment.params import RockScale, SegmentParams
from stockpile_ros.segment.pipeline import analyse_mesh


def _mesh_info() -> MeshInfo:
    scale = ScaleRecord('target', 0.5, 0.002, {'fit': 0.001}, 'ChArUco')
    poses = [KeyframePose(7, [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0], 'kf_00000_000000.png')]
    return MeshInfo(scale=scale, units='m', keyframes=poses, poisson={'depth': 9})


def test_each_record_survives_its_round_trip(tmp_path: Path) -> None:
    camera = CameraModel.from_fov(64, 48, 60.0)
    odometry = OdometryEntry([1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], camera_position=[1, 0, 1.5])
    record = KeyframeRecord('kf.png', 5, 2, camera, odometry, 'parallax', 3.5, {'later': 1})
    back = KeyframeRecord.from_line(record.to_line())
    assert back.odometry == odometry and back.extra == {'later': 1}
    assert back.camera is not None and np.array_equal(back.camera.k, camera.k)
    sparse = SparseSummary(3, 4, 0.75, 1, 100, 0.4, 900.0, 'prior', [], 'sequential', '',
                           'incremental', ['c.png'], [ModelImages(3, ['a', 'b', 'd'])])  # fmt: skip
    dense = DenseSummary('sgbm-pairs', False, 1000, voxel=math.nan)
    for item, cls in ((sparse, SparseSummary), (dense, DenseSummary), (_mesh_info(), MeshInfo)):
        path = tmp_path / f'{cls.__name__}.json'
        save(item, path)
        again = load(cls, path)
        assert to_json(again) == to_json(item)
    # JSON has no NaN: an undefined number is null on disk and NaN again when read.
    assert json.loads((tmp_path / 'DenseSummary.json').read_text())['voxel'] is None
    assert math.isnan(load(DenseSummary, tmp_path / 'DenseSummary.json').voxel)


def test_a_newer_or_another_schema_is_refused(tmp_path: Path) -> None:
    path = tmp_path / 'mesh.json'
    data = to_json(_mesh_info())
    path.write_text(json.dumps({**data, 'schema': 'stockpile-mesh/2'}))
    with pytest.raises(ArtefactError, match='newer'):
        load(MeshInfo, path)
    path.write_text(json.dumps({**data, 'schema': 'stockpile-report/2'}))
    with pytest.raises(ArtefactError, match='expected'):
        load(MeshInfo, path)


@pytest.mark.parametrize(
    ('change', 'why'),
    [
        ({'units': 'feet'}, 'not one of'),
        ({'keyframes': [{'stamp_ns': 'soon', 'position': [], 'orientation_xyzw': []}]}, 'int'),
        ({'keyframes': [{'position': [0, 0, 0]}]}, 'stamp_ns'),
        ({'scale': {'method': 'none'}}, 'units'),  # metres without a scale
        ({'ground_inliers': True}, 'int'),
    ],
)
def test_a_bad_field_is_refused_with_where_it_is(change: dict[str, object], why: str) -> None:
    data = {**to_json(_mesh_info()), **change}
    with pytest.raises(ArtefactError, match=why):
        from_json(MeshInfo, data)


@pytest.fixture(scope='module')
def report() -> Report:
    """A report of a small synthetic pile, metric, checked against a class, every part filled."""
    v, f, _ = small_pile()
    mesh, check = check_mesh(LabelledMesh(v, f, np.zeros(len(f), dtype=np.int32)), 'pile.ply')
    analysis = analyse_mesh(mesh.vertices, mesh.faces, mesh_info=_mesh_info(),
                            spec=load_class_table()['classes']['I'], source='pile.ply')  # fmt: skip
    made = analysis.report
    made.mesh.check = check
    made.mesh.model_to_stockpile = SimilarityRecord(2.0)
    made.provenance = ProvenanceRecord(
        input_path='pile.ply', keyframes_used=1, scale=ProvenanceScale('target', 0.002, 'ChArUco')
    )
    return made


def test_the_report_survives_its_round_trip(tmp_path: Path, report: Report) -> None:
    assert report.rocks and report.gradation.spec.limits and report.gradation.sieves
    path = tmp_path / 'report.json'
    save(report, path)
    again = load(Report, path)
    assert again == report
    assert to_json(again) == to_json(report)
    assert json.loads(path.read_text())['schema'] == 'stockpile-report/3'


def test_a_report_missing_a_field_or_of_another_version_is_refused(
    tmp_path: Path, report: Report
) -> None:
    path = tmp_path / 'report.json'
    data = to_json(report)
    for version, why in ((4, 'newer'), (2, 'older')):
        path.write_text(json.dumps({**data, 'schema': f'stockpile-report/{version}'}))
        with pytest.raises(ArtefactError, match=why) as info:
            load(Report, path)
        assert str(path) in str(info.value)
    rock = {k: v for k, v in data['rocks'][0].items() if k != 'b'}
    path.write_text(json.dumps({**data, 'rocks': [rock]}))
    with pytest.raises(ArtefactError, match=r"report\.json\.rocks\[0\]: 'b' missing"):
        load(Report, path)
    spec = {**data['gradation']['spec'], 'verdict': 'MAYBE'}
    path.write_text(json.dumps({**data, 'gradation': {**data['gradation'], 'spec': spec}}))
    with pytest.raises(ArtefactError, match=r'gradation\.spec\.verdict: .* not one of'):
        load(Report, path)
    path.write_text(json.dumps({**data, 'units': 'model'}))
    with pytest.raises(ArtefactError, match='units'):
        load(Report, path)


def test_docs_name_every_field() -> None:
    doc = (Path(__file__).resolve().parent.parent / 'docs' / 'formats.md').read_text()
    records = (KeyframeRecord, OdometryEntry, KeyframeSummary, SparseSummary, ModelImages,
               DenseSummary, MeshInfo, ScaleRecord, SimilarityRecord, KeyframePose, Report,
               RockRecord, GradationCurve, GradationRecord, Intervals, ClassDecision, LimitRow,
               RosinRammler, Sieve, SegmentationRecord, RockScale, MeasureRecord, MeshRecord,
               MeshCheck, ProvenanceRecord, ProvenanceScale)  # fmt: skip
    for record in records:
        names = [f.name for f in dataclasses.fields(record) if f.name != 'extra']
        # The parameters a record extends are those of the parameter table (config/stockpile.yaml).
        for parameters in (SegmentParams, MeasureParams):
            if issubclass(record, parameters):
                inherited = {f.name for f in dataclasses.fields(parameters)}
                names = [name for name in names if name not in inherited]
        missing = [name for name in names if f'`{name}`' not in doc and f'"{name}"' not in doc]
        assert not missing, f'{record.__name__}: docs/formats.md does not name {missing}'
