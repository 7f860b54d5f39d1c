"""Channels of a run file read a window or a chunk at a time, for the analyses that stream (afrf, skeleton,
presliding; docs/long-runs.md). Every read is checked as :func:`hilbench.analysis.record.numeric` checks a whole
channel, and a message names the record's sample index, so a streamed analysis refuses what the whole one refuses.

A progress callback ``progress(done, total)`` (samples) is the only way an analysis reports progress: the CLI turns
it into a bar, a script may pass its own or none."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from hilbench.analysis.record import numeric
from hilbench.analysis.runfile import LINEAR_ALIASES, open_run

#: samples per chunk when the caller does not choose (a few float64 channels: a few MiB)
CHUNK = 1 << 18

Progress = Callable[[int, int], None]


class ChannelReader:
    """A run file held open to read samples ``[start, stop)`` of its channels (context manager)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._run = open_run(self.path)

    def __enter__(self) -> ChannelReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._run.close()

    @property
    def n_samples(self) -> int:
        return int(self._run.n_samples)

    def has(self, name: str) -> bool:
        key = LINEAR_ALIASES.get(name, name) if self._run.axis == "linear" else name
        return key in self._run.channels

    def protocol_array(self, name: str) -> np.ndarray | None:
        return self._run.protocol_array(name) if name in self._run.protocol_array_names else None

    def read(self, name: str, start: int, stop: int) -> np.ndarray:
        """Samples ``[start, stop)`` of channel ``name`` as float64, checked (one-line AnalysisError)."""
        return numeric(self._run.channel(name, start, stop), name, f"{self.path} (samples from {start})")

    def chunks(self, names: Sequence[str], chunk: int = CHUNK, start: int = 0, stop: int | None = None,
               progress: Progress | None = None) -> Iterator[tuple[int, list[np.ndarray]]]:
        """``(first sample, [channel arrays])`` of at most ``chunk`` samples each, in order, from ``start`` to
        ``stop`` (default the end); ``progress(done, total)`` after each chunk."""
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        total = max(0, stop - start)
        for a in range(start, stop, max(1, int(chunk))):
            b = min(a + chunk, stop)
            yield a, [self.read(n, a, b) for n in names]
            if progress is not None:
                progress(b - start, total)
