"""The segmentation component: a ``SurfaceMesh`` in; rocks, measures and gradation out.

The surface is written into this component's own work folder (``surface/``) and segmented from
there, so the segmentation may run on another machine than the reconstruction. A run publishes
the segmented cloud, the rock markers, the rocks and the gradation, the capture warnings, a
``stockpile/segment`` diagnostic and a ``DONE`` status with the verdict; or a ``FAILED`` status.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..artefacts import WorkFolder
from ..recon.collector import CollectorState
from ..result import Report
from ..ros.messages import MessageFactory
from ..ros.publications import (
    Publication,
    capture_warnings,
    diagnostics,
    segmentation_outputs,
    status,
)
from ..runner import Outcome, run_segmentation
from ..segment.provenance import Provenance
from ..settings import Settings
from .handoff import read_surface
from .reconstruction import Emit

__all__ = ['SegmentationComponent', 'result_lines', 'verdict']


def result_lines(report: Report) -> list[str]:
    """Return what a run found, for people: rocks and D50, then the class and its verdict.

    Sizes are in metres only when the run had a metric scale (``units`` is ``model`` else);
    the verdict is PASS, FAIL (with the reasons), UNDECIDED (an interval straddles a limit) or
    REFUSED (no metric scale).
    """
    g = report.gradation
    unit = 'm' if report.metric else 'model units'
    d50 = 'undefined' if g.d50 is None else f'{g.d50:.3f} {unit}'
    lines = [f'{len(report.rocks)} rocks, D50 {d50}']
    spec = g.spec
    if spec.class_name:
        why = '; '.join(spec.reasons)
        said = spec.verdict
        lines.append(
            f'class {spec.class_name}: {said}' + (f': {why}' if why and said != 'PASS' else '')
        )
    return lines


def verdict(report: Report) -> str:
    """Return the results in one line (the final status's message)."""
    return '; '.join(result_lines(report))


class SegmentationComponent:
    """Segment each surface received.

    Args:
        settings: Parameters at start (work folder).
        f: Message factory.

    """

    def __init__(self, settings: Settings, f: MessageFactory) -> None:
        self.f = f
        self.work = WorkFolder(settings.work_dir)
        self.held = CollectorState()

    def on_surface(self, msg: Any, log_ns: int) -> list[Publication]:
        """Write the surface into ``surface/``; segment it with :meth:`run` next."""
        self.held = CollectorState(keyframes=int(msg.keyframes), coverage=float(msg.coverage))
        try:
            read_surface(msg, self.work.surface)
        except (ValueError, json.JSONDecodeError) as exc:
            text = f'surface unusable: {exc}'
            return [
                diagnostics(self.f, log_ns, 'segment', 'ERROR', text),
                status(self.f, log_ns, 'FAILED', 'segment', self.held, text),
            ]
        return []

    def run(
        self,
        settings: Settings,
        stamp_ns: int,
        emit: Emit,
        result_dir: Path | None = None,
        provenance: Provenance | None = None,
    ) -> Outcome:
        """Segment the surface last received; publications go to ``emit``.

        Args:
            settings: Parameters now.
            stamp_ns: Stamp of the results (the surface's).
            emit: Receives each group of publications.
            result_dir: Result folder (``<work_dir>/result`` by default).
            provenance: What the result was made from (a replay names its bag; live, the
                surface received is the input).

        Returns:
            The segmentation's outcome.

        """
        f, held = self.f, self.held
        outcome = run_segmentation(settings, self.work.surface, result_dir, provenance)
        if not outcome.ok or outcome.analysis is None:
            emit([
                diagnostics(f, stamp_ns, 'segment', 'ERROR', outcome.reason,
                            {'advice': outcome.advice}),
                status(f, stamp_ns, 'FAILED', 'segment', held, outcome.reason, outcome.advice),
            ])  # fmt: skip
            return outcome
        report = outcome.analysis.report
        max_faces = int(settings.values['display_max_faces'])
        emit(segmentation_outputs(f, stamp_ns, outcome.analysis, settings.frame_id, max_faces))
        emit(capture_warnings(f, stamp_ns, report))
        rocks = len(report.rocks)
        emit([
            diagnostics(f, stamp_ns, 'segment', 'OK', f'{rocks} rocks',
                        {'rocks': rocks, 'seconds': round(outcome.seconds['segment'], 2),
                         'd50': report.gradation.d50}),
            status(f, stamp_ns, 'DONE', 'segment', held, verdict(report)),
        ])  # fmt: skip
        return outcome
