"""Friction identification of a record: :func:`analyse` (a :class:`hilbench.analysis.record.Record` in, an
:class:`~hilbench.analysis.identification.identify.Identification` out) and :func:`report` (the figures). The CLI
(``hilbench identify``), the GUI's run browser and campaign steps call these two, so one run gives one answer."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from hilbench.analysis.identification.identify import Identification
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.record import Record


def analyse(record: Record, settings: LipSettings | None = None, *, method: str = "lip",
            validation: Record | None = None) -> Identification:
    """Identify the Maxwell-slip model (J, k_i, Delta_i, b, options of ``settings``) of ``record``; score it on
    ``validation`` when given (never fitted). The torque timing is the record's (the loader resolved it); a
    displacement-driven record is fitted with J = 0 unless ``settings.fixed_inertia`` says otherwise."""
    from hilbench.analysis.errors import AnalysisError
    from hilbench.analysis.identification.identify import identify
    from hilbench.analysis.identification.maxwell_fit import LipSettings

    settings = replace(settings or LipSettings(), timing=record.timing)
    if record.kind == "displacement-driven" and settings.fixed_inertia is None:
        settings = replace(settings, fixed_inertia=0.0)
    if validation is not None:
        if validation.axis != record.axis:
            raise AnalysisError(f"{validation.path}: a {validation.axis} axis; {record.path} is {record.axis}")
        if validation.kind != record.kind:
            raise AnalysisError(f"{validation.path} is {validation.kind}; {record.path} is {record.kind}")
        if validation.timing != record.timing:  # each run's torque is aligned by its own timing
            raise AnalysisError(f"{validation.path}: torque timing {validation.timing}, {record.path}: "
                                f"{record.timing}; give both runs the same --torque-timing")
    return identify(record.arrays(), method=method, validate=validation.arrays() if validation else None,
                    settings=settings, record=record.kind)


def report(result: Identification, out_dir: str | Path, save: Callable | None = None) -> list[Path]:
    """The identification's figures (virgin curve, fit, residuals, hysteresis per run) as PNGs in ``out_dir``."""
    from hilbench.analysis.identification.plots import write_plots

    return write_plots(result, out_dir) if save is None else write_plots(result, out_dir, save=save)
