"""Reconstruction: keyframes, Structure-from-Motion, dense cloud, scale, ground and Poisson mesh."""

from __future__ import annotations

from ..artefacts import WorkFolder
from .options import ReconOptions
from .pipeline import STAGES, reconstruct

__all__ = ['STAGES', 'ReconOptions', 'WorkFolder', 'reconstruct']
