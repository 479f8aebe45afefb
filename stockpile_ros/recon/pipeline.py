"""The reconstruction stages chained over the work folder of ``docs/formats.md``.

``keyframes/`` -> ``sparse/`` -> ``dense/`` -> ``mesh/``; every stage reads only what the previous
ones wrote, so any stage can be rerun alone, and the keyframe stage resumes after a restart.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from ..artefacts import KeyframeSummary, StageResult, WorkFolder
from ..errors import StockpileError
from .options import ReconOptions
from .stages import run_dense_stage, run_keyframes, run_mesh_stage, run_sfm_stage

__all__ = ['STAGES', 'reconstruct']

STAGES = ('keyframes', 'sfm', 'dense', 'mesh')


def reconstruct(
    source: Path | None,
    work_dir: Path,
    options: ReconOptions,
    stage: str = 'all',
    report: Callable[[str, StageResult, float], None] | None = None,
    keyframe_stage: Callable[[Path, WorkFolder, ReconOptions], KeyframeSummary] | None = None,
) -> dict[str, StageResult]:
    """Run one stage or all of them in order.

    Args:
        source: Bag, folder of photos or video (needed by the keyframe stage only).
        work_dir: The work folder.
        options: Tuning.
        stage: One of :data:`STAGES` or ``"all"``.
        report: Called after each stage with its name, result and duration [s].
        keyframe_stage: Runs the keyframe stage (:func:`run_keyframes` by default; the command
            line hands bags to the keyframe component, :mod:`stockpile_ros.bagdrive`).

    Returns:
        Each stage's result by name.

    """
    if stage != 'all' and stage not in STAGES:
        raise StockpileError(f'unknown stage {stage!r}; choose from {", ".join(STAGES)}, all')
    work = WorkFolder(work_dir)
    results: dict[str, StageResult] = {}
    for name in STAGES if stage == 'all' else (stage,):
        start = time.perf_counter()
        if name == 'keyframes':
            if source is None:
                raise StockpileError('the keyframes stage needs a SOURCE (bag, photos or video)')
            results[name] = (keyframe_stage or run_keyframes)(source, work, options)
        elif name == 'sfm':
            results[name] = run_sfm_stage(work, options)
        elif name == 'dense':
            results[name] = run_dense_stage(work, options)
        else:
            results[name] = run_mesh_stage(work, options)
        if report is not None:
            report(name, results[name], time.perf_counter() - start)
    return results
