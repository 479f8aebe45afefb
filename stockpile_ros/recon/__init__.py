"""Reconstruction: keyframes, Structure-from-Motion, dense cloud, scale, ground and Poisson mesh.

:func:`~stockpile_ros.recon.pipeline.reconstruct` chains the stages of :mod:`.stages`; the scale
policy is :mod:`.scaling`, the options :mod:`.options`; each stage's record is in
:mod:`stockpile_ros.artefacts`.
"""

from __future__ import annotations

__all__: list[str] = []
