"""Friction identification of a record: :func:`analyse` (a :class:`hilbench.analysis.record.Record` in, an
:class:`~hilbench.analysis.identification.identify.Identification` out) and :func:`report` (the figures). The CLI
(``hilbench identify``), the GUI's run browser and campaign steps call these two, so one run gives one answer."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hilbench.analysis.identification.identify import Identification
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.record import Record


def _settings_for(record: Record, settings: LipSettings | None) -> LipSettings:
    """``settings`` with the record's torque timing (the loader resolved it), and J = 0 for a displacement-driven
    record unless ``settings.fixed_inertia`` says otherwise."""
    from hilbench.analysis.identification.maxwell_fit import LipSettings

    settings = replace(settings or LipSettings(), timing=record.timing)
    if record.kind == "displacement-driven" and settings.fixed_inertia is None:
        settings = replace(settings, fixed_inertia=0.0)
    return settings


def analyse(record: Record, settings: LipSettings | None = None, *, method: str = "lip",
            validation: Record | None = None) -> Identification:
    """Identify the Maxwell-slip model (J, k_i, Delta_i, b, options of ``settings``) of ``record``; score it on
    ``validation`` when given (never fitted). The torque timing is the record's (the loader resolved it); a
    displacement-driven record is fitted with J = 0 unless ``settings.fixed_inertia`` says otherwise."""
    from hilbench.analysis.identification.identify import identify
    from hilbench.analysis.protocol import Inputs, check_validation

    settings = _settings_for(record, settings)
    if validation is not None:  # each run's torque is aligned by its own timing
        check_validation(Inputs([record]), Inputs([validation]), ("axis", "kind", "timing"))
    return identify(record.arrays(), method=method, validate=validation.arrays() if validation else None,
                    settings=settings, record=record.kind)


#: bytes per sample of the array path (loader copies, regressors of the kept rows, figures) and its fixed part,
#: from the peaks measured at 10 kHz (0.6 M samples: 184 MiB, 1.8 M: 280 MiB; docs/long-runs.md), with margin
ARRAY_BYTES_PER_SAMPLE = 150
ARRAY_BYTES_FIXED = 160 << 20
#: the streamed path: blocks of 16 384 samples, the thinned path and the filters (268 MiB at 18 M samples)
STREAM_BYTES_PER_SAMPLE = 8
STREAM_BYTES_FIXED = 220 << 20


def array_cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse` on whole arrays of ``samples`` (training plus validation)."""
    return ARRAY_BYTES_FIXED + ARRAY_BYTES_PER_SAMPLE * int(samples)


def stream_cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse_stream` over ``samples`` (training plus validation)."""
    return STREAM_BYTES_FIXED + STREAM_BYTES_PER_SAMPLE * int(samples)


def analyse_stream(record: Record, source, settings: LipSettings | None = None, *, method: str = "lip",
                   validation: tuple[Record, object] | None = None) -> Identification:
    """:func:`analyse` on records read chunk by chunk (``hilbench.analysis.record.stream_record``): the same model
    and figures to 1e-9 (tests/analysis/identification/test_chunked.py), in memory bounded by the block size
    whatever the record's length; no curves for the figures (docs/long-runs.md)."""
    from hilbench.analysis.identification.identify import identify_chunks
    from hilbench.analysis.protocol import Inputs, check_validation

    settings = _settings_for(record, settings)
    val_source = None
    if validation is not None:  # both runs' chunks are read at one rate
        val, val_source = validation
        check_validation(Inputs([record]), Inputs([val]), ("axis", "kind", "timing", "sample_rate"))
    return identify_chunks(source, record.sample_rate, axis=record.axis, validate=val_source, settings=settings,
                           record=record.kind, method=method,
                           validate_samples=val.n_samples if validation is not None else None)


def report(result: Identification, out_dir: str | Path, runs: dict[str, str | Path] | None = None) -> list[Path]:
    """The identification's figures (virgin curve, fit, residuals, hysteresis per run) as PNGs in ``out_dir``;
    ``runs`` (role "train"/"validation" -> run file) names the runs in the titles."""
    from hilbench.analysis.identification.plots import write_plots

    return write_plots(result, out_dir, runs)
