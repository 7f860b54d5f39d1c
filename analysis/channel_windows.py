"""Channels of a run file read a window or a chunk at a time, for the analyses that stream (afrf, skeleton,
presliding; docs/long-runs.md). Every read is checked as :func:`hilbench.analysis.record.numeric` checks a whole
channel, and a message names the record's sample index, so a streamed analysis refuses what the whole one refuses.

A progress callback ``progress(done, total)`` (samples) is the only way an analysis reports progress: the CLI turns
it into a bar, a script may pass its own or none."""

from __future__ import annotations

from collections.abc import Callable

from hilbench.analysis.record import READER_CHUNK, ChannelReader  # noqa: F401 (re-exported: the one chunk reader)

#: samples per chunk when the caller does not choose (a few float64 channels: a few MiB)
CHUNK = READER_CHUNK

Progress = Callable[[int, int], None]
