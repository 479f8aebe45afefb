"""Hostile inputs through the command line: image bombs, malformed meshes, meshes in other units.

Each case runs ``stockpile_ros.cli.main`` in this process and asserts the exit code, that the
message names the cause, that no traceback was printed, and the peak of traced memory (numpy
reports its buffers to tracemalloc, so an array the size a header claims would show).
"""

from __future__ import annotations

import json
import struct
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from segment_fixtures import height_field, small_pile

from stockpile_ros.artefacts import load
from stockpile_ros.bagio.writer import BagWriter
from stockpile_ros.cli import main
from stockpile_ros.meshcheck import MeshCheck
from stockpile_ros.meshio import LabelledMesh, write_labelled_mesh
from stockpile_ros.result import Report
from stockpile_ros.ros import messages as m

S = 1_000_000_000
MB = 1 << 20
# Every bomb here would allocate at least 290 MB if its header were believed.
PEAK_BOUND = 200 * MB
IMAGE_TOPIC = '/cam/image_raw'


def _run(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str, int]:
    """Exit code, stdout, stderr and traced peak memory [bytes] of one command."""
    capsys.readouterr()
    tracemalloc.start()
    try:
        code = main(argv)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    out, err = capsys.readouterr()
    assert 'Traceback' not in err and 'Traceback' not in out
    return code, out, err, peak


# --- image bombs in bags ---------------------------------------------------------------------


def _bag(path: Path, messages: list[Any]) -> Path:
    with BagWriter(path) as bag:
        for i, msg in enumerate(messages):
            bag.write(IMAGE_TOPIC, msg, S + i * S // 10)
    return path


def _png(width: int, height: int) -> bytes:
    """A valid all-black grey PNG of any size; the zlib stream of zero rows stays small."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body)
        return struct.pack('>I', len(body)) + kind + body + struct.pack('>I', crc)

    packer = zlib.compressobj(9)
    row = b'\x00' * (width + 1)  # filter byte and the row
    rows = [packer.compress(row * 100) for _ in range(height // 100)]
    rows.append(packer.compress(row * (height % 100)) + packer.flush())
    ihdr = struct.pack('>IIBBBBB', width, height, 8, 0, 0, 0, 0)
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', ihdr) + chunk(b'IDAT', b''.join(rows))
            + chunk(b'IEND', b''))  # fmt: skip


def _jpeg(width: int, height: int) -> bytes:
    """A small real JPEG whose frame header is rewritten to claim ``width`` x ``height``."""
    ok, buf = cv2.imencode('.jpg', np.full((16, 16, 3), 90, np.uint8))
    assert ok
    data = bytearray(buf.tobytes())
    sof = data.index(b'\xff\xc0')
    data[sof + 5 : sof + 9] = struct.pack('>HH', height, width)
    return bytes(data)


def _raw(f: Any, width: int, height: int, step: int, data: bytes) -> Any:
    msg = m.image(f, np.zeros((1, 1), np.uint8), S, 'cam')
    msg.width, msg.height, msg.step, msg.data = width, height, step, np.frombuffer(data, np.uint8)
    return msg


def _compressed(f: Any, fmt: str, data: bytes) -> Any:
    msg = m.compressed_image(f, np.zeros((4, 4), np.uint8), S, 'cam')
    msg.format, msg.data = fmt, np.frombuffer(data, np.uint8)
    return msg


IMAGE_CASES: dict[str, tuple[Callable[[Any], Any], tuple[str, ...]]] = {
    # 1x1 mono8 with a step of 4e9: the old decoder padded the missing bytes with zeros (4 GB).
    'step bomb': (
        lambda f: _raw(f, 1, 1, 4_000_000_000, b'\x07'),
        ('step 4000000000', 'larger than the whole data'),
    ),
    # 1x50000 with a row pitch of 50000 bytes: 2.5 GB were padded.
    'step bomb, tall': (
        lambda f: _raw(f, 1, 50_000, 50_000, b'\x07' * 50_000),
        ('data holds 50000 bytes', 'needs'),
    ),
    'raw width*height bomb': (
        lambda f: _raw(f, 20_000, 20_000, 20_000, b'\x00' * 64),
        ('20000x20000', 'megapixels'),
    ),
    'png header bomb': (lambda f: _compressed(f, 'png', _png(10_000, 10_000)), ('10000x10000',)),
    'jpeg header bomb': (lambda f: _compressed(f, 'jpeg', _jpeg(20_000, 20_000)), ('20000x20000',)),
    'truncated jpeg': (lambda f: _compressed(f, 'jpeg', _jpeg(16, 16)[:200]), ('truncated JPEG',)),
    'jpeg without a frame header': (
        lambda f: _compressed(f, 'jpeg', b'\xff\xd8\xff\xe0\x00\x04ab\xff\xda\x00\x02\xff\xd9'),
        ('before any frame header',),
    ),
}


@pytest.mark.parametrize('case', list(IMAGE_CASES))
def test_image_bombs_are_bad_messages_named_by_info(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    make, words = IMAGE_CASES[case]
    with BagWriter(tmp_path / 'bag') as bag:
        bad = make(bag.factory)
        good = (m.compressed_image if hasattr(bad, 'format') else m.image)(
            bag.factory, np.zeros((6, 8), np.uint8), S, 'cam'
        )
        bag.write(IMAGE_TOPIC, bad, S)
        bag.write(IMAGE_TOPIC, good, 2 * S)
    code, out, _, peak = _run(capsys, ['info', str(tmp_path / 'bag')])
    assert code == 0  # bad messages are reported, not fatal
    assert '1/2 decoded' in out and 'message 0' in out
    for word in words:
        assert word in out
    assert peak < PEAK_BOUND


def test_replay_of_step_bombs_skips_every_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        for i in range(3):
            bag.write(IMAGE_TOPIC, _raw(bag.factory, 1, 1, 4_000_000_000, b'\x07'), S + i * S)
    code, _, err, peak = _run(
        capsys, ['replay', str(tmp_path / 'bag'), '--out', str(tmp_path / 'o')]
    )
    assert code == 1 and peak < PEAK_BOUND
    report = (tmp_path / 'o').rglob('*')
    assert any(p.name == 'replay.mcap' for p in report)
    assert 'keyframe' in err or 'frames' in err


# --- photo folders ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ('name', 'data'),
    [('a_huge.png', lambda: _png(10_000, 10_000)), ('a_huge.jpg', lambda: _jpeg(20_000, 20_000))],
)
def test_huge_photo_in_a_folder_is_refused_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, data: Callable[[], bytes]
) -> None:
    photos = tmp_path / 'photos'
    photos.mkdir()
    (photos / name).write_bytes(data())
    cv2.imwrite(str(photos / 'b_ok.png'), np.zeros((8, 8, 3), np.uint8))
    argv = ['reconstruct', str(photos), '--work', str(tmp_path / 'w'), '--stage', 'keyframes']
    code, _, err, peak = _run(capsys, argv)
    assert code == 2 and peak < PEAK_BOUND
    lines = err.strip().splitlines()
    assert len(lines) == 1 and name in lines[0] and 'megapixels' in lines[0]


# --- meshes ----------------------------------------------------------------------------------


def _ply(path: Path, vertices: Any, faces: Any) -> Path:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    write_labelled_mesh(path, LabelledMesh(v, f, np.zeros(len(f), dtype=np.int32)))
    return path


TETRA_V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
TETRA_F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
# The first face as written: its vertex count, then indices 0 and 2 as little-endian int32.
FIRST_FACE = b'\x03' + struct.pack('<ii', 0, 2)


def _edit_header(path: Path, old: bytes, new: bytes) -> Path:
    raw = path.read_bytes()
    assert old in raw
    path.write_bytes(raw.replace(old, new, 1))
    return path


MESH_CASES: dict[str, tuple[Callable[[Path], Path], tuple[str, ...]]] = {
    'zero vertices': (lambda p: _ply(p, np.zeros((0, 3)), np.zeros((0, 3))), ('0 vertices',)),
    'nan vertices': (
        lambda p: _ply(p, [*TETRA_V[:3], [np.nan, 0, 1]], TETRA_F),
        ('1 of 4 vertices are not finite',),
    ),
    'inf vertices': (lambda p: _ply(p, [*TETRA_V[:3], [np.inf, 0, 1]], TETRA_F), ('not finite',)),
    'index out of range': (
        lambda p: _ply(p, TETRA_V, [*TETRA_F[:3], [1, 2, 9]]),
        ('outside 0..3', 'face 3'),
    ),
    'negative index': (lambda p: _ply(p, TETRA_V, [*TETRA_F[:3], [-1, 2, 3]]), ('outside 0..3',)),
    'blank header line': (
        lambda p: _edit_header(_ply(p, TETRA_V, TETRA_F), b'\nelement face', b'\n\nelement face'),
        ('header line', 'blank'),
    ),
    'garbage in the header': (
        lambda p: _edit_header(_ply(p, TETRA_V, TETRA_F), b'property float y', b'propty float y'),
        ("unknown keyword 'propty'",),
    ),
    'unknown property type': (
        lambda p: _edit_header(_ply(p, TETRA_V, TETRA_F), b'property float y', b'property flt y'),
        ('expected "property TYPE NAME"',),
    ),
    'truncated body': (
        lambda p: p.write_bytes(_ply(p, TETRA_V, TETRA_F).read_bytes()[:-20]) and p,
        ('claims 4 vertex, 4 face', 'truncated'),
    ),
    'vertex count 1000x': (
        lambda p: _edit_header(
            _ply(p, TETRA_V, TETRA_F), b'element vertex 4', b'element vertex 4000'
        ),
        ('claims 4000 vertex',),
    ),
    'face count 1e12': (
        lambda p: _edit_header(
            _ply(p, TETRA_V, TETRA_F), b'element face 4', b'element face 1000000000000'
        ),
        ('claims 4 vertex, 1000000000000 face',),
    ),
    'ascii counts over the file size': (
        lambda p: (
            p.write_text(
                'ply\nformat ascii 1.0\nelement vertex 100000000\nproperty float x\n'
                'property float y\nproperty float z\nelement face 1\n'
                'property list uchar int vertex_indices\nend_header\n0 0 0\n3 0 0 0\n'
            )
            and p
        ),
        ('claims 100000000 vertex', 'at least'),
    ),
    'a face count that misaligns the faces': (
        lambda p: _edit_header(_ply(p, TETRA_V, TETRA_F), FIRST_FACE, b'\x04' + FIRST_FACE[1:]),
        ('faces have fewer than 3 corners',),
    ),
    'a face of two corners': (
        lambda p: (
            p.with_suffix('.obj').write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n')
            and p.with_suffix('.obj')
        ),
        ('1 faces have fewer than 3 corners (first: face 1, 2)',),
    ),
    'all faces degenerate': (
        lambda p: _ply(p, [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2], [0, 0, 1]]),
        ('all 2 faces are degenerate',),
    ),
    'not a mesh at all': (lambda p: p.write_bytes(b'\x00garbage' * 10) and p, ('not a triangle',)),
    'obj with bad content': (
        lambda p: (
            p.with_suffix('.obj').write_text('v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\nxyz\n')
            and p.with_suffix('.obj')
        ),
        ('mesh.obj',),
    ),
    'obj with nan vertices': (
        lambda p: (
            p.with_suffix('.obj').write_text('v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n')
            and p.with_suffix('.obj')
        ),
        ('not finite',),
    ),
    'missing file': (lambda p: p.with_name('nothing.ply'), ('no such mesh file',)),
}


@pytest.mark.parametrize('case', list(MESH_CASES))
def test_malformed_meshes_are_refused_with_the_cause(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    make, words = MESH_CASES[case]
    mesh = make(tmp_path / 'mesh.ply')
    out = tmp_path / 'result'
    code, _, err, peak = _run(capsys, ['segment', str(mesh), '--out', str(out)])
    assert code == 2, err
    assert err.startswith('stockpile segment: error: ') and len(err.strip().splitlines()) <= 2
    for word in words:
        assert word in err
    assert not out.exists() and peak < PEAK_BOUND


def _segment(
    capsys: pytest.CaptureFixture[str], mesh: Path, out: Path, *args: str
) -> tuple[int, str, Report]:
    code, _, err, peak = _run(capsys, ['segment', str(mesh), '--out', str(out), *args])
    assert code == 0, err
    assert peak < PEAK_BOUND
    return code, err, load(Report, out / 'report.json')


def _check(report: Report) -> MeshCheck:
    assert report.mesh.check is not None
    return report.mesh.check


def _rocks(report: Report) -> list[float]:
    """Each rock's intermediate dimension and volume, in report order (mass is null unscaled)."""
    return [value for r in report.rocks for value in (r.b, r.volume)]


def test_tripled_and_degenerate_faces_are_dropped_counted_and_give_the_clean_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    v, f, _ = small_pile()
    _, _, clean = _segment(capsys, _ply(tmp_path / 'clean.ply', v, f), tmp_path / 'c')
    assert _check(clean).duplicate_faces == 0
    # Each face three times (the copies with their vertices rotated and reversed), then faces
    # that repeat a vertex and a zero-area face over three collinear vertices.
    far = len(v)
    line = np.array([[0.5, 0.5, 0.0], [0.6, 0.5, 0.0], [0.7, 0.5, 0.0]])
    bad = [[0, 0, 1], [2, 3, 3], [far, far + 1, far + 2]]
    faces = np.concatenate([f, f[:, [1, 2, 0]], f[:, ::-1], bad])
    mesh = _ply(tmp_path / 'tripled.ply', np.concatenate([v, line]), faces)
    _, err, tripled = _segment(capsys, mesh, tmp_path / 't')
    check = _check(tripled)
    assert (check.duplicate_faces, check.degenerate_faces) == (2 * len(f), 3)
    assert check.faces_kept == len(f)
    assert f'{2 * len(f)} duplicate faces dropped' in err and '3 degenerate faces' in err
    assert _rocks(tripled) == pytest.approx(_rocks(clean))
    assert len(tripled.rocks) == len(clean.rocks) > 0


def test_a_mesh_whose_vertices_collapsed_onto_each_other_is_refused_with_the_cause(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import open3d as o3d

    v, f = _two_boulders()
    _, _, clean = _segment(capsys, _ply(tmp_path / 'clean.ply', v, f), tmp_path / 'c')
    # Geographic coordinates (5e5 m east, 5e6 m north) in single precision, as a tool computing
    # so leaves them: steps of 3.1 cm and 0.5 m against the grid's 8.4 mm.
    far = v + np.array([5e5, 5e6, 300.0])
    path = _ply(tmp_path / 'single.ply', far.astype(np.float32), f)
    code, _, err, _ = _run(
        capsys, ['segment', str(path), '--units', 'm', '--out', str(tmp_path / 's')]
    )
    assert code != 0 and not (tmp_path / 's').exists()
    assert 'faces have zero area over three vertices, which fell onto each other' in err
    assert 'single-precision numbers as large as 5e+06, on steps of 0.5 there' in err
    # The same coordinates in double precision: measured as the mesh near the origin is.
    double = tmp_path / 'double.ply'
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(far), o3d.utility.Vector3iVector(f))
    assert o3d.io.write_triangle_mesh(str(double), mesh)
    _, err, kept = _segment(capsys, double, tmp_path / 'd', '--units', 'm')
    assert 'degenerate' not in err
    assert len(kept.rocks) == len(clean.rocks) > 0


def test_a_mesh_stored_face_by_face_is_joined_and_gives_the_clean_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # As STL stores a mesh: three vertices of its own for every face, none shared. Unjoined, no
    # face bordered another, and the run found no rock.
    v, f = _two_boulders()
    _, _, clean = _segment(capsys, _ply(tmp_path / 'clean.ply', v, f), tmp_path / 'c')
    apart = _ply(tmp_path / 'apart.ply', v[f.ravel()], np.arange(3 * len(f)).reshape(-1, 3))
    _, err, joined = _segment(capsys, apart, tmp_path / 'j')
    assert f'{3 * len(f) - len(np.unique(f))} vertices joined' in err
    assert _check(joined).faces_kept == len(f)
    assert _rocks(joined) == pytest.approx(_rocks(clean))
    assert len(joined.rocks) == len(clean.rocks) > 0


def _two_boulders() -> tuple[np.ndarray, np.ndarray]:
    """Two boulders on flat ground, a grid of 120 x 120 vertices, no two at one position."""

    def bumps(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        z = np.zeros_like(x)
        for cx, cy, r in ((0.1, 0.0, 0.15), (-0.2, 0.2, 0.1)):
            z = np.maximum(z, np.sqrt(np.clip(r**2 - (x - cx) ** 2 - (y - cy) ** 2, 0, None)))
        return z

    return height_field(bumps, 0.5, 120)


def _polygon_ply(path: Path, vertices: np.ndarray, faces: list[list[int]]) -> Path:
    """A binary PLY of polygons as Blender writes them, each face's rock_id after its corners."""
    head = (f'ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n'
            'property float x\nproperty float y\nproperty float z\n'
            f'element face {len(faces)}\nproperty list uchar int vertex_indices\n'
            'property int rock_id\nend_header\n')  # fmt: skip
    body = vertices.astype('<f4').tobytes() + b''.join(
        struct.pack(f'<B{len(face)}ii', len(face), *face, 0) for face in faces
    )
    path.write_bytes(head.encode() + body)
    return path


def test_quads_and_polygons_are_cut_into_triangles(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    v, f = _two_boulders()
    # The grid's squares, each written as the triangles a, b, c and a, c, d were.
    half = len(f) // 2
    quads = np.column_stack([f[:half], f[half:, 2]]).tolist()
    _, _, triangles = _segment(capsys, _ply(tmp_path / 'tri.ply', v, f), tmp_path / 't')
    assert len(triangles.rocks) >= 2
    sizes = sorted(_rocks(triangles))
    # Quads; quads and triangles mixed; an OBJ of quads with slashes and negative indices.
    mixed = [face for q in quads[:40] for face in (q[:3], [q[0], q[2], q[3]])] + quads[40:]
    obj = tmp_path / 'quads.obj'
    obj.write_text(''.join(f'v {x} {y} {z}\nvt 0 0\n' for x, y, z in v)
                   + ''.join('f ' + ' '.join(f'{i - len(v)}/1' for i in q) + '\n'
                             for q in quads))  # fmt: skip
    for name, mesh in (
        ('quads', _polygon_ply(tmp_path / 'quads.ply', v, quads)),
        ('mixed', _polygon_ply(tmp_path / 'mixed.ply', v, mixed)),
        ('obj', obj),
    ):
        _, _, report = _segment(capsys, mesh, tmp_path / name)
        assert _check(report).faces_kept == len(f), name
        assert sorted(_rocks(report)) == pytest.approx(sizes, rel=1e-6), name


def test_many_zero_length_edges_do_not_hang_the_segmentation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # More degenerate faces than good ones: their zero edges would be the median edge.
    v, f, _ = small_pile()
    zero = np.repeat(np.arange(len(f) * 2)[:, None] % len(v), 3, axis=1)
    mesh = _ply(tmp_path / 'mesh.ply', v, np.concatenate([f, zero]))
    _, _, report = _segment(capsys, mesh, tmp_path / 'r')
    assert _check(report).degenerate_faces == 2 * len(f)
    assert report.segmentation.seconds < 60


@pytest.mark.parametrize(
    ('scale', 'units', 'words'),
    [
        (1000.0, 'mm', ('looks like millimetres', '--units mm')),
        (1e-3, 'km', ('kilometres', '--units km')),
    ],
)
def test_a_mesh_in_other_units_is_refused_unless_its_units_are_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], scale: float, units: str,
    words: tuple[str, ...],
) -> None:  # fmt: skip
    v, f, _ = small_pile()
    mesh = _ply(tmp_path / 'mesh.ply', v * scale, f)
    code, _, err, _ = _run(capsys, ['segment', str(mesh), '--out', str(tmp_path / 'r')])
    assert code == 2 and 'implausible size' in err
    for word in words:
        assert word in err
    # Units given make a metric result (masses in kg); the clean mesh is in metres.
    _, _, clean = _segment(
        capsys, _ply(tmp_path / 'clean.ply', v, f), tmp_path / 'c', '--units', 'm'
    )
    _, _, scaled = _segment(capsys, mesh, tmp_path / 's', '--units', units)
    assert _rocks(scaled) == pytest.approx(_rocks(clean), rel=1e-4)
    assert _check(scaled).units == units


def test_explicit_units_on_an_implausibly_small_mesh_finish_and_warn(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Every length of the segmentation scales with the mesh's edges, so a mesh 1000 times too
    # small in metres is cut as the right-sized one; the user said metres, and is warned.
    v, f, _ = small_pile()
    mesh = _ply(tmp_path / 'mesh.ply', v * 1e-3, f)
    argv = ['segment', str(mesh), '--out', str(tmp_path / 'r'), '--units', 'm']
    code, _, err, _ = _run(capsys, argv)
    assert code == 0 and 'implausible' in err
    report = load(Report, tmp_path / 'r' / 'report.json')
    assert not _check(report).plausible
    assert any('implausible' in w for w in report.warnings)


# --- bags with bad poses, cameras and sizes; parameters; output folders; interruptions --------

CAM = '/camera/image_raw'


def _camera_bag(
    path: Path,
    frames: int = 6,
    *,
    odometry: Callable[[int], tuple[tuple[float, ...], tuple[float, ...]]] | None = None,
    info: tuple[int, int] | None = (64, 48),
    size: Callable[[int], tuple[int, int]] = lambda i: (48, 64),
) -> Path:
    """A small camera bag: random frames, CameraInfo of ``info`` (w, h), odometry if given."""
    with BagWriter(path) as bag:
        f = bag.factory
        for i in range(frames):
            stamp = S + i * S // 10
            pixels = (np.random.default_rng(i).random((*size(i), 3)) * 255).astype(np.uint8)
            bag.write(CAM, m.image(f, pixels, stamp, 'camera_optical'), stamp)
            if info is not None:
                k = np.array([[60.0, 0, info[0] / 2], [0, 60.0, info[1] / 2], [0, 0, 1]])
                camera = m.CameraModel(info[0], info[1], k, np.zeros(5), 'plumb_bob', 'cam')
                bag.write('/camera/camera_info', m.camera_info(f, camera, stamp), stamp)
            if odometry is not None:
                position, quat = odometry(i)
                bag.write('/odom', m.odometry(f, stamp, position, quat), stamp)
    return path


BAD_BAGS = {
    'zero quaternion in odometry': (
        lambda p: _camera_bag(p, odometry=lambda i: ((0.1 * i, 0, 0), (0, 0, 0, 0))),
        'zero quaternion',
    ),
    'NaN position in odometry': (
        lambda p: _camera_bag(p, odometry=lambda i: ((float('nan'), 0, 0), (0, 0, 0, 1))),
        'non-finite value',
    ),
    'CameraInfo of another size': (
        lambda p: _camera_bag(p, info=(640, 480)),
        'CameraInfo is 640x480 but the images are 64x48',
    ),
    'images that change size': (
        lambda p: _camera_bag(p, size=lambda i: (48, 64) if i < 3 else (96, 128)),
        'image size changed from 64x48 to 128x96',
    ),
    'no image topic': (
        lambda p: _camera_bag(p, frames=0, odometry=lambda i: ((0, 0, 0), (0, 0, 0, 1))),
        'no Image or CompressedImage topic',
    ),
}


@pytest.mark.parametrize('case', list(BAD_BAGS))
def test_bad_bags_are_reported_by_cause(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    make, words = BAD_BAGS[case]
    bag = make(tmp_path / 'bag')
    code, out, err, peak = _run(capsys, ['replay', str(bag), '--out', str(tmp_path / 'out')])
    assert code in (1, 2) and words in err, err  # no result from six frames, or refused
    assert 'intrinsics CameraInfo' not in out or case != 'CameraInfo of another size'
    assert peak < PEAK_BOUND


def test_not_a_bag_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / 'o'
    for source in (tmp_path / 'notes.txt', tmp_path / 'empty'):
        source.write_text('x') if source.suffix else source.mkdir()
        code, _, err, _ = _run(capsys, ['replay', str(source), '--out', str(out)])
        assert code == 2 and str(source) in err
    assert not out.exists()  # refused before the folder was claimed


BAD_PARAMETERS = {
    'segment.threshold=.nan': 'not a finite number',
    'measure.specific_gravity=.inf': 'not a finite number',
    'sfm.matcher=bogus': "'bogus' is not one of",
    'sfm.overlap=0': 'is outside [1, 1000]',
    'recon.target=charuco:1x1:0.08:0.06:DICT_4X4_50': 'at least 2 x 2 squares',
    'sfm.nosuch=1': "unknown parameter 'sfm.nosuch'",
    'sfm.max_features=many': 'expected int',
    'gradation.spec_class=XIV': "'XIV' is not one of",
}


@pytest.mark.parametrize('assignment', list(BAD_PARAMETERS))
def test_bad_parameters_are_refused_before_any_stage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], assignment: str
) -> None:
    bag, out = _camera_bag(tmp_path / 'bag'), tmp_path / 'out'
    code, _, err, peak = _run(capsys, ['replay', str(bag), '--out', str(out), '--set', assignment])
    assert code == 2 and BAD_PARAMETERS[assignment] in err and peak < PEAK_BOUND
    assert not out.exists()  # refused before anything was written


def test_output_folders_that_cannot_take_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag, other = _camera_bag(tmp_path / 'bag'), _camera_bag(tmp_path / 'other', 7)
    (tmp_path / 'file').write_text('x')
    stray = tmp_path / 'stray'
    stray.mkdir()
    (stray / 'report.json').write_text('{}')
    out = tmp_path / 'out'
    assert _run(capsys, ['replay', str(bag), '--out', str(out)])[0] == 1
    cases = {
        str(tmp_path / 'file'): 'is a file',
        str(tmp_path / 'file' / 'sub'): str(tmp_path / 'file'),
        str(stray): 'holds no run record',
    }
    for folder, words in cases.items():
        code, _, err, _ = _run(capsys, ['replay', str(bag), '--out', folder])
        assert code == 2 and words in err, (folder, err)
    code, _, err, _ = _run(capsys, ['replay', str(other), '--out', str(out), '--resume'])
    assert code == 2 and 'another input' in err
    code, _, err, _ = _run(capsys, ['replay', str(bag), '--out', str(out)])
    assert code == 2 and '--resume continues it' in err


def test_an_interrupted_replay_says_so_in_its_bag_and_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from stockpile_ros.components import KeyframeComponent

    bag, out = _camera_bag(tmp_path / 'bag'), tmp_path / 'out'
    seen = KeyframeComponent.on_image

    def on_image(self: KeyframeComponent, msg: Any, log_ns: int) -> Any:
        if self.collector.state.frames == 3:
            raise KeyboardInterrupt  # Ctrl-C in the middle of the bag
        return seen(self, msg, log_ns)

    monkeypatch.setattr(KeyframeComponent, 'on_image', on_image)
    code, _, err, _ = _run(capsys, ['replay', str(bag), '--out', str(out)])
    assert code == 130 and 'interrupted' in err
    assert not (out / 'replay.mcap').exists() and (out / 'replay.mcap.partial').is_file()
    assert json.loads((out / 'run.json').read_text())['state'] == 'interrupted'
    from rosbags.highlevel import AnyReader

    readable = tmp_path / 'partial.mcap'  # as docs/formats.md says: rename it to open it
    readable.write_bytes((out / 'replay.mcap.partial').read_bytes())
    with AnyReader([readable]) as reader:
        statuses = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                    if c.topic == '/stockpile/status']  # fmt: skip
    assert statuses[-1].state == 5 and 'interrupted' in statuses[-1].message
