"""How much of a long presliding record the analysis reads (docs/long-runs.md, "presliding: long records").

The analysis averages the record in blocks of m = ceil(n/MAX_SAMPLES) samples (:func:`~.analyse.block_means`). That
is harmless while a block stays short against the time between reversals, and destroys the physics once it does
not: the block mean at a turning point falls short of the turn, and past a branch's length the reversals average
away. A presliding excitation is a nested path played over and over, so a long record is many repeats of the same
path, and the sample budget is better spent on a few repeats at the path's own resolution than on all of them
averaged away.

:func:`plan_span` keeps the whole record when its blocks leave at least :data:`KEEP_BLOCKS_PER_BRANCH` of them in
its shortest branch between turning points, so every record the old rule served is analysed as before. Otherwise it
shortens the block to at most 1/:data:`SPAN_BLOCKS_PER_BRANCH` of that branch, and the analysis reads only the first
MAX_SAMPLES blocks of that length, cut at the end of the last whole repeat of the path that fits (or at the last
turning point, if no repeat is found): the result is that of a record holding only those repeats. The turning
points are found on block means, as the analysis finds them, so noise on the position makes no false turns. Each
judgement reads a head of the record that only shrinks, so the memory is bounded by the budget, not by the record.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hilbench.analysis.presliding.reversals import find_reversals

#: a record whose blocks (ceil(n/MAX_SAMPLES)) hold at least this many in its shortest branch between turning points
#: is analysed whole, as before. On a cosine-shaped stroke the block mean at a turn then falls short of it by at most
#: pi^2/(12*16^2) = 0.3 % of the stroke. Measured on the nested path at 20 kHz (2000-sample strokes), against
#: blocks of 20: break-away within about 0.4 %, the presliding distance within about 2 % (16 to 17 blocks a stroke,
#: blocks not aligned with the strokes; the 60 s record's aligned blocks of 120 give 0.7455 and 0.994 mrad); 10
#: blocks a stroke lose 2.9 % of the break-away, 5 blocks 13 %.
KEEP_BLOCKS_PER_BRANCH = 16
#: a span cut from a longer record is averaged in blocks of at most this fraction of its shortest branch: the
#: budget is spent on resolving the path rather than on more repeats of it (measured as above, 31 to 34 blocks a
#: stroke: break-away within 0.1 % and the presliding distance within 0.6 % of blocks of 20)
SPAN_BLOCKS_PER_BRANCH = 32
#: turning points of two repeats of the path agree within this fraction of the smallest travel between turns
REPEAT_TOLERANCE = 0.2

#: block means of the position over the first ``head`` samples in blocks of ``m`` (the tail is dropped)
XMeans = Callable[[int, int], np.ndarray]
#: the raw position samples [start, stop)
ReadX = Callable[[int, int], np.ndarray]


@dataclass(frozen=True)
class Span:
    """The part of a record the analysis reads: the first ``samples`` samples."""

    samples: int
    block: int  # samples per block the span was judged at (the analysis uses ceil(samples/max_samples) <= block)
    branch: int  # the shortest branch between turning points, samples (to within a block)
    repeats: int  # whole repeats of the path in the span; 0 when no repeat was found

    def warning(self, n: int, fs: float, max_samples: int) -> str:
        """One line for ``PreslidingResult.warnings``: the span analysed (s) and why."""
        what = (f"{self.repeats} whole repeats of the path" if self.repeats
                else "up to the last turning point that fits; no repeat of the path was found")
        return (f"analysed the first {self.samples / fs:.4g} s of {n / fs:.4g} s ({what}): averaging the whole "
                f"record into {max_samples} blocks would leave fewer than {KEEP_BLOCKS_PER_BRANCH} blocks in the "
                f"shortest branch between reversals ({self.branch / fs:.3g} s) and average the reversals away; "
                f"the span keeps {SPAN_BLOCKS_PER_BRANCH} or more")


def x_means(x: np.ndarray, m: int, head: int) -> np.ndarray:
    """:data:`XMeans` on an array (the same reduction as the block means of the analysis)."""
    k = (min(head, x.size) // m) * m
    return np.asarray(x[:k], float).reshape(-1, m).mean(axis=1)


def plan_span(n: int, max_samples: int, hysteresis: float, means: XMeans, read_x: ReadX) -> Span | None:
    """The span to analyse of a record of ``n`` samples, or None for the whole record (module docstring).
    ``hysteresis``: the analysis's reversal hysteresis (m or rad)."""
    m = whole = max(1, -(-n // max_samples))
    stage = _stage(means, m, n, hysteresis)
    if stage is None or stage[2] >= KEEP_BLOCKS_PER_BRANCH:  # no turning point: the analysis says so, on all of it
        return None
    while stage is not None and stage[2] < SPAN_BLOCKS_PER_BRANCH and m > 1:
        # the turning points seen at a coarse block may be fewer than the path's (averaged away), so the branch
        # measured there is no bound: shorten the block by it and judge again on the shorter head
        m = max(1, min(m - 1, stage[2] * m // SPAN_BLOCKS_PER_BRANCH))
        stage = _stage(means, m, min(n, max_samples * m), hysteresis)
    if stage is None:  # the head before the first turning point: nothing better than the whole record
        return None
    # the longest block the branch measured at this one allows: a finer block than needed would spend the budget
    # on fewer repeats
    longer = min(stage[2] * m // SPAN_BLOCKS_PER_BRANCH, whole - 1)
    if longer > m:
        again = _stage(means, longer, max_samples * longer, hysteresis)
        if again is not None and again[2] >= SPAN_BLOCKS_PER_BRANCH:
            m, stage = longer, again
    xb, rev, shortest = stage
    repeat = _period(xb[rev])
    last = (rev.size // repeat) * repeat - 1 if repeat else rev.size - 1
    end = _turn_sample(read_x, xb, rev, last, m, max_samples * m)
    return Span(end, m, shortest * m, rev.size // repeat if repeat else 0)


def _stage(means: XMeans, m: int, head: int, hysteresis: float) -> tuple[np.ndarray, np.ndarray, int] | None:
    """(block means of the first ``head`` samples in blocks of ``m``, their turning points, the shortest branch
    between them in blocks, the virgin ramp included), or None with no turning point."""
    xb = means(m, head)
    rev = find_reversals(xb, hysteresis)
    if rev.size == 0:
        return None
    return xb, rev, int(np.min(np.diff(np.concatenate([[0], rev]))))


def _period(turns: np.ndarray) -> int:
    """The fewest turning points after which the sequence ``turns`` repeats (even: a repeat ends going the way it
    began), seen at least twice; 0 when it does not repeat."""
    if turns.size < 4:
        return 0
    tol = REPEAT_TOLERANCE * float(np.min(np.abs(np.diff(turns))))
    for p in range(2, turns.size // 2 + 1, 2):
        if np.all(np.abs(turns[p:] - turns[:-p]) <= tol):
            return p
    return 0


def _turn_sample(read_x: ReadX, xb: np.ndarray, rev: np.ndarray, i: int, m: int, head: int) -> int:
    """The raw sample of turning point ``rev[i]`` (a block index): the extreme within a block either side of its
    block, the last one of a plateau there (as find_reversals takes it)."""
    before = xb[rev[i - 1]] if i > 0 else xb[0]
    is_max = xb[rev[i]] > before
    a, b = max(0, (int(rev[i]) - 1) * m), min(head, (int(rev[i]) + 2) * m)
    seg = read_x(a, b)
    flipped = seg[::-1]
    return a + seg.size - 1 - int(np.argmax(flipped) if is_max else np.argmin(flipped))
