"""The progress bar of the analysis commands (the only one): the ``progress(done, total)`` callback the analyses
take (hilbench.analysis.channel_windows), drawn by tqdm on standard error once the work has lasted 2 s, with the
count and an ETA; ``-q``/``--quiet`` silences it."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from tqdm import tqdm

#: seconds before a bar appears: shorter work stays silent
DELAY_S = 2.0


@contextmanager
def progress_bar(desc: str, unit: str = "sample") -> Iterator[Callable[[int, int], None]]:
    """Context manager yielding the callback; the bar is closed on exit."""
    from hilbench.bench.storage import outputs

    bars: list[tqdm] = []

    def update(done: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(total=total, unit=unit, unit_scale=unit == "sample", desc=desc, file=sys.stderr,
                             disable=True if outputs.verbosity == 0 else None, delay=DELAY_S,
                             dynamic_ncols=True, mininterval=0.5))
        bar = bars[0]
        if bar.total != total:
            bar.total = total
        bar.update(done - bar.n)

    try:
        yield update
    finally:
        for bar in bars:
            bar.close()
