"""Triangle meshes with a per-face label (rock id, 0 for ground or unassigned) as binary PLY.

open3d's PLY writer keeps no per-face properties, so this small reader/writer does: vertices with
optional colours, faces with an ``int rock_id``. MeshLab, CloudCompare and Blender open these files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = ['LabelledMesh', 'read_labelled_mesh', 'write_labelled_mesh']


@dataclass
class LabelledMesh:
    """A triangle mesh whose faces carry an integer label.

    Attributes:
        vertices: Nx3 float64 vertex positions [m].
        faces: Mx3 int64 vertex indices.
        labels: M int32 face labels (rock id, 0 = ground or unassigned).
        colors: Nx3 uint8 vertex colours, or None.

    """

    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]
    labels: npt.NDArray[np.int32]
    colors: npt.NDArray[np.uint8] | None = None


def write_labelled_mesh(path: str | Path, mesh: LabelledMesh) -> None:
    """Write ``mesh`` as binary little-endian PLY with a ``rock_id`` face property."""
    nv, nf = len(mesh.vertices), len(mesh.faces)
    if len(mesh.labels) != nf:
        raise ValueError(f'{len(mesh.labels)} labels for {nf} faces')
    lines = ['ply', 'format binary_little_endian 1.0', 'comment stockpile_ros labelled mesh']
    lines += [f'element vertex {nv}', 'property float x', 'property float y', 'property float z']
    vdesc: list[tuple[str, str]] = [('x', '<f4'), ('y', '<f4'), ('z', '<f4')]
    if mesh.colors is not None:
        lines += ['property uchar red', 'property uchar green', 'property uchar blue']
        vdesc += [('red', 'u1'), ('green', 'u1'), ('blue', 'u1')]
    lines += [
        f'element face {nf}',
        'property list uchar int vertex_indices',
        'property int rock_id',
    ]
    lines.append('end_header')
    verts = np.empty(nv, dtype=vdesc)
    for i, axis in enumerate('xyz'):
        verts[axis] = mesh.vertices[:, i]
    if mesh.colors is not None:
        for i, channel in enumerate(('red', 'green', 'blue')):
            verts[channel] = mesh.colors[:, i]
    faces = np.empty(nf, dtype=[('n', 'u1'), ('v', '<i4', (3,)), ('rock_id', '<i4')])
    faces['n'] = 3
    faces['v'] = mesh.faces
    faces['rock_id'] = mesh.labels
    with Path(path).open('wb') as out:
        out.write(('\n'.join(lines) + '\n').encode('ascii'))
        out.write(verts.tobytes())
        out.write(faces.tobytes())


_PLY_TYPES = {
    'char': 'i1', 'uchar': 'u1', 'short': '<i2', 'ushort': '<u2', 'int': '<i4', 'uint': '<u4',
    'float': '<f4', 'double': '<f8', 'int8': 'i1', 'uint8': 'u1', 'int16': '<i2', 'uint16': '<u2',
    'int32': '<i4', 'uint32': '<u4', 'float32': '<f4', 'float64': '<f8',
}  # fmt: skip


def read_labelled_mesh(path: str | Path) -> LabelledMesh:
    """Read a binary little-endian PLY written by :func:`write_labelled_mesh`.

    Faces without a ``rock_id`` property get label 0.

    Raises:
        ValueError: The file is not a binary little-endian triangle PLY.

    """
    raw = Path(path).read_bytes()
    end = raw.find(b'end_header\n')
    if not raw.startswith(b'ply') or end < 0:
        raise ValueError(f'{path}: not a PLY file')
    header_lines = raw[:end].decode('ascii').splitlines()
    if 'format binary_little_endian 1.0' not in header_lines:
        raise ValueError(f'{path}: only binary little-endian PLY is supported')
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in header_lines:
        words = line.split()
        if words[0] == 'element':
            elements.append((words[1], int(words[2]), []))
        elif words[0] == 'property' and words[1] == 'list':
            if words[4] != 'vertex_indices' and words[4] != 'vertex_index':
                raise ValueError(f'{path}: unsupported list property {words[4]}')
            elements[-1][2].append(('n', _PLY_TYPES[words[2]]))
            elements[-1][2].append(('v', _PLY_TYPES[words[3]] + ',(3,)'))
        elif words[0] == 'property':
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
    offset = end + len(b'end_header\n')
    data: dict[str, npt.NDArray[np.void]] = {}
    for name, count, props in elements:
        dtype = np.dtype([(p, t.split(',')[0], (3,)) if ',' in t else (p, t) for p, t in props])
        data[name] = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
        offset += dtype.itemsize * count
    v, f = data['vertex'], data['face']
    if np.any(f['n'] != 3):
        raise ValueError(f'{path}: only triangle faces are supported')
    names = v.dtype.names or ()
    colors = None
    if {'red', 'green', 'blue'} <= set(names):
        colors = np.stack([v['red'], v['green'], v['blue']], axis=1).astype(np.uint8)
    fnames = f.dtype.names or ()
    labels = f['rock_id'] if 'rock_id' in fnames else np.zeros(len(f))
    return LabelledMesh(
        vertices=np.stack([v['x'], v['y'], v['z']], axis=1).astype(np.float64),
        faces=np.asarray(f['v'], dtype=np.int64),
        labels=np.asarray(labels, dtype=np.int32),
        colors=colors,
    )
