"""Rocks out of the mesh: the paper's curvature search (Eq. 2), per-rock measures, the gradation.

:func:`~stockpile_ros.segment.pipeline.analyse_mesh` runs it all and
:func:`~stockpile_ros.segment.report.write_result_folder` writes the result folder; the modules are
usable alone: :mod:`.adjacency`, :mod:`.criterion`, :mod:`.region` (vectorised search), :mod:`.bfs`
(per-face reference), :mod:`.segmentation`, :mod:`.measure`, :mod:`.gradation`, :mod:`.render`,
:mod:`.report`, :mod:`.scoring` and :mod:`.synthetic` (test scenes).
"""

from __future__ import annotations

__all__: list[str] = []
