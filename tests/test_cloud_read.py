"""Point cloud readers: PLY (ASCII, binary; normals, colours), OBJ, LAS, LAZ, XYZ/CSV/TXT."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import open3d as o3d
import pytest

from stockpile_ros.cloud import is_mesh_file, read_cloud
from stockpile_ros.errors import MeshError

RNG = np.random.default_rng(4)
POINTS = RNG.uniform(-1, 1, (50, 3)) + np.array([1000.0, 2000.0, 30.0])
NORMALS = RNG.normal(size=(50, 3))
NORMALS /= np.linalg.norm(NORMALS, axis=1, keepdims=True)
COLORS = RNG.integers(0, 256, (50, 3)).astype(np.uint8)


def _ply(path: Path, normals: bool, colors: bool, ascii: bool) -> Path:
    """A points-only PLY as survey tools write it: double x, y, z, float normals, uchar colours."""
    fields = [('x', '<f8'), ('y', '<f8'), ('z', '<f8')]
    if normals:
        fields += [('nx', '<f4'), ('ny', '<f4'), ('nz', '<f4')]
    if colors:
        fields += [('red', 'u1'), ('green', 'u1'), ('blue', 'u1')]
    rows = np.zeros(len(POINTS), dtype=fields)
    for i, axis in enumerate('xyz'):
        rows[axis] = POINTS[:, i]
        if normals:
            rows['n' + axis] = NORMALS[:, i]
    for i, channel in enumerate(('red', 'green', 'blue')):
        if colors:
            rows[channel] = COLORS[:, i]
    kinds = {'<f8': 'double', '<f4': 'float', 'u1': 'uchar'}
    header = ['ply', f'format {"ascii" if ascii else "binary_little_endian"} 1.0',
              f'element vertex {len(rows)}', *(f'property {kinds[k]} {n}' for n, k in fields),
              'end_header']  # fmt: skip
    with path.open('wb') as out:
        out.write(('\n'.join(header) + '\n').encode())
        if ascii:
            out.write(''.join(' '.join(repr(v) for v in row.tolist()) + '\n' for row in rows)
                      .encode())  # fmt: skip
        else:
            out.write(rows.tobytes())
    return path


@pytest.mark.parametrize('ascii', [True, False])
@pytest.mark.parametrize(('normals', 'colors'), [(False, False), (True, False), (True, True)])
def test_ply_points(tmp_path: Path, ascii: bool, normals: bool, colors: bool) -> None:
    path = _ply(tmp_path / 'c.ply', normals, colors, ascii)
    assert not is_mesh_file(path)
    cloud = read_cloud(path)
    assert cloud.format == 'ply'
    np.testing.assert_allclose(cloud.points, POINTS, rtol=0, atol=1e-9)
    assert (cloud.normals is not None) == normals
    if normals:
        assert cloud.normals is not None
        np.testing.assert_allclose(cloud.normals, NORMALS, atol=1e-5)
    assert (cloud.colors is not None) == colors
    if colors:
        np.testing.assert_array_equal(cloud.colors, COLORS)


def test_ply_with_faces_is_a_mesh(tmp_path: Path) -> None:
    mesh = o3d.geometry.TriangleMesh.create_box()
    path = tmp_path / 'box.ply'
    o3d.io.write_triangle_mesh(path, mesh)
    assert is_mesh_file(path)


def test_obj_vertices_and_faces(tmp_path: Path) -> None:
    lines = [f'v {x} {y} {z} {r / 255} {g / 255} {b / 255}'
             for (x, y, z), (r, g, b) in zip(POINTS, COLORS, strict=True)]  # fmt: skip
    cloud_path = tmp_path / 'cloud.obj'
    cloud_path.write_text('\n'.join(['# points only', *lines]) + '\n')
    assert not is_mesh_file(cloud_path)
    cloud = read_cloud(cloud_path)
    np.testing.assert_allclose(cloud.points, POINTS)
    assert cloud.colors is not None
    np.testing.assert_array_equal(cloud.colors, COLORS)
    mesh_path = tmp_path / 'mesh.obj'
    mesh_path.write_text('\n'.join([*lines, 'f 1 2 3']) + '\n')
    assert is_mesh_file(mesh_path)


@pytest.mark.parametrize('suffix', ['.las', '.laz'])
def test_las_and_laz(tmp_path: Path, suffix: str) -> None:
    header = laspy.LasHeader(point_format=2, version='1.2')
    header.offsets = POINTS.min(axis=0)
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    las = laspy.LasData(header)
    las.x, las.y, las.z = POINTS[:, 0], POINTS[:, 1], POINTS[:, 2]
    # 16-bit channels, as LAS stores them.
    las.red, las.green, las.blue = (COLORS.astype(np.uint16) * 257).T
    path = tmp_path / f'survey{suffix}'
    las.write(str(path))
    assert not is_mesh_file(path)
    cloud = read_cloud(path)
    assert cloud.format == suffix[1:]
    np.testing.assert_allclose(cloud.points, POINTS, atol=1e-4)
    assert cloud.normals is None
    assert cloud.colors is not None
    np.testing.assert_array_equal(cloud.colors, COLORS)


def _table(rows: np.ndarray, sep: str, header: str = '') -> str:
    body = '\n'.join(sep.join(f'{v:.9g}' for v in row) for row in rows)
    return (header + '\n' if header else '') + body + '\n'


def test_text_without_header(tmp_path: Path) -> None:
    xyz = tmp_path / 'a.xyz'
    xyz.write_text(_table(POINTS, ' '))
    cloud = read_cloud(xyz)
    np.testing.assert_allclose(cloud.points, POINTS)
    assert cloud.normals is None and cloud.colors is None
    with_normals = tmp_path / 'b.txt'
    with_normals.write_text(_table(np.hstack([POINTS, NORMALS]), '\t'))
    cloud = read_cloud(with_normals)
    assert cloud.normals is not None and cloud.colors is None
    with_colors = tmp_path / 'c.csv'
    with_colors.write_text(_table(np.hstack([POINTS, COLORS]), ','))
    cloud = read_cloud(with_colors)
    assert cloud.normals is None and cloud.colors is not None
    np.testing.assert_array_equal(cloud.colors, COLORS)
    both = tmp_path / 'd.xyz'
    both.write_text(_table(np.hstack([POINTS, NORMALS, COLORS]), ' '))
    cloud = read_cloud(both)
    assert cloud.normals is not None and cloud.colors is not None


def test_text_with_header(tmp_path: Path) -> None:
    # Columns in another order, named as CloudCompare writes them.
    csv = tmp_path / 'a.csv'
    rows = np.hstack([COLORS, POINTS, NORMALS])
    csv.write_text(_table(rows, ',', '//Red,Green,Blue,X,Y,Z,Nx,Ny,Nz'))
    cloud = read_cloud(csv)
    np.testing.assert_allclose(cloud.points, POINTS)
    assert cloud.normals is not None and cloud.colors is not None
    np.testing.assert_allclose(cloud.normals, NORMALS, atol=1e-8)
    np.testing.assert_array_equal(cloud.colors, COLORS)
    bad = tmp_path / 'b.csv'
    bad.write_text(_table(POINTS, ',', 'east,north,height'))
    with pytest.raises(MeshError, match='names no x, y and z'):
        read_cloud(bad)


def test_text_faults(tmp_path: Path) -> None:
    ambiguous = tmp_path / 'a.xyz'
    ambiguous.write_text(_table(np.hstack([POINTS, 3.5 * NORMALS]), ' '))
    with pytest.raises(MeshError, match='neither unit normals nor'):
        read_cloud(ambiguous)
    extra = tmp_path / 'b.xyz'
    extra.write_text(_table(np.hstack([POINTS, POINTS[:, :1]]), ' '))
    cloud = read_cloud(extra)
    assert cloud.points.shape == (50, 3)
    assert any('rest ignored' in w for w in cloud.warnings)
    holes = tmp_path / 'c.xyz'
    rows = POINTS.copy()
    rows[3, 1] = np.nan
    holes.write_text(_table(rows, ' '))
    cloud = read_cloud(holes)
    assert len(cloud.points) == 49
    assert any('non-finite' in w for w in cloud.warnings)
    with pytest.raises(MeshError, match='unknown point cloud suffix'):
        read_cloud(tmp_path / 'x.e57')
    with pytest.raises(MeshError, match='no such file'):
        read_cloud(tmp_path / 'missing.las')
    not_las = tmp_path / 'd.las'
    not_las.write_bytes(b'not a las file')
    with pytest.raises(MeshError, match='LAS/LAZ'):
        read_cloud(not_las)
