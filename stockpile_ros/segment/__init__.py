"""Rocks out of the mesh: the paper's curvature search (Eq. 2), per-rock measures, the gradation.

:func:`~stockpile_ros.segment.pipeline.analyse_mesh` runs it all and
:func:`~stockpile_ros.segment.report.write_result_folder` writes the result folder; the modules are
usable alone: :mod:`.adjacency`, :mod:`.criterion`, :mod:`.region` (vectorised search),
:mod:`.segmentation` (chaining :mod:`.params`, :mod:`.valleys`, :mod:`.cleanup`), :mod:`.measure`,
:mod:`.gradation`, :mod:`.render` and :mod:`.report`. Test scenes and the per-face reference search
are tools (:mod:`stockpile_ros.tools`).
"""

from __future__ import annotations

__all__: list[str] = []
