"""A record cut into the head an analysis fits and the tail it is validated on: one run as two records.

Campaign steps (``hilbench analyse``) have one run where the analyses' front doors take a training and a
validation record; they cut the run here and call the same front doors as ``hilbench identify``, ``compare`` and
``residual``, so a campaign row reads as those commands read the head and the tail written as two run files.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.record import Record


def window(record: Record, start: int, stop: int, label: str) -> Record:
    """Samples ``start:stop`` of ``record`` (every loaded channel), its time restarting at 0 s as a run file of
    those samples would; ``label`` goes into the record's notes (reports say what part of the run they read).
    The samples before ``start`` travel along as ``Record.lead``: a model is scored on the window from the friction
    state the measured path left (analysis.scoring), so a tail scores as the same span inside the whole run."""
    n = record.t.size
    if not 0 <= start < stop <= n:
        raise AnalysisError(f"{record.path}: samples {start}:{stop} are not a window of its {n} samples")
    rows = slice(start, stop)

    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[rows]

    lead = record.lead
    if start > 0 and record.position is not None and record.torque is not None:
        # the run before the window (views unless the record is itself a window): a model scored on the window
        # starts its friction state from the measured path since the run's start (analysis.scoring)
        x0, tau0 = np.asarray(record.position)[:start], np.asarray(record.torque)[:start]
        lead = (x0, tau0) if lead is None else (np.concatenate([lead[0], x0]), np.concatenate([lead[1], tau0]))
    return replace(record, t=record.t[rows] - record.t[start], position=cut(record.position),
                   torque=cut(record.torque), channels={k: np.asarray(v)[rows] for k, v in record.channels.items()},
                   n_samples=stop - start, notes=[*record.notes, f"{label}: samples {start}:{stop} of {n}"],
                   lead=lead)


def split(record: Record, validation_fraction: float) -> tuple[Record, Record | None]:
    """(head, tail): the last ``validation_fraction`` of the samples (rounded to a sample) held out as the tail;
    a fraction of 0 gives the whole record and no tail."""
    if not 0 <= validation_fraction < 1:
        raise AnalysisError(f"validation fraction {validation_fraction:g} is not in [0, 1)")
    n = record.t.size
    cut = int(round(n * (1 - validation_fraction)))
    if validation_fraction == 0:
        return record, None
    if cut < 2 or n - cut < 2:
        raise AnalysisError(f"{record.path}: {n} samples cannot be cut into a head and a tail "
                            f"(validation fraction {validation_fraction:g})")
    return window(record, 0, cut, "head"), window(record, cut, n, "validation tail")
