"""Reconstruction: keyframes, Structure-from-Motion, dense cloud, scale, ground and Poisson mesh."""

from __future__ import annotations

from .pipeline import STAGES, ReconOptions, WorkFolder, reconstruct

__all__ = ['STAGES', 'ReconOptions', 'WorkFolder', 'reconstruct']
