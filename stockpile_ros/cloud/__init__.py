"""Point clouds and foreign meshes in: read (PLY, OBJ, LAS/LAZ, XYZ/CSV), level, Poisson-mesh.

ROS-free: ``stockpile segment`` meshes a cloud file through it, and the reconstruction component
a PointCloud2 stream accumulated in the odometry frame (:mod:`.accumulate`).
"""

from .level import level_transform, parse_up, trend_up
from .mesh import CloudOptions, cloud_segment_params, mesh_cloud, point_spacing, poisson_depth
from .read import CLOUD_SUFFIXES, Cloud, is_mesh_file, read_cloud

__all__ = [
    'CLOUD_SUFFIXES',
    'Cloud',
    'CloudOptions',
    'cloud_segment_params',
    'is_mesh_file',
    'level_transform',
    'mesh_cloud',
    'parse_up',
    'point_spacing',
    'poisson_depth',
    'read_cloud',
    'trend_up',
]
