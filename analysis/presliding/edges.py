"""Edge-pinned points of a quantised presliding record: where the encoder count changes, the true displacement is
exactly on the boundary between the two counts.

A position loop on a quantised encoder holds the contact at a count edge: the count toggles between k and k+1
while the true position stays within a small fraction of a count of the boundary. Averaged over such a dwell,
the force belongs to a displacement known exactly, not to a count centre known to +-half a step. The path
through the successive dwells is monotone between them, so the Maxwell-slip elements see the same turning
points as on the true path, and the stop-operator model can be fitted on the dwells alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: crossings of one boundary at most this many samples apart belong to one dwell
DWELL_GAP = 50
#: samples at rest averaged for the starting force
REST_SAMPLES = 50
#: samples of the moving average that finds the extreme force of an excursion past an edge
EXTREME_SMOOTHING = 21


@dataclass(frozen=True)
class EdgePoints:
    """The starting point and the dwells at count edges, in time order.

    ``x`` (m or rad): x[0] is the first sample's count (the relaxed state, known to +-half a step), then the
    boundaries; ``force`` (N or N*m): the mean force over each dwell; ``first``/``last``: the samples each
    dwell spans; ``crossings``: edge crossings in each dwell (0 for the starting point)."""

    x: np.ndarray
    force: np.ndarray
    first: np.ndarray
    last: np.ndarray
    crossings: np.ndarray

    @property
    def size(self) -> int:
        return int(self.x.size)


def edge_points(x: np.ndarray, force: np.ndarray, step: float, gap: int = DWELL_GAP, min_crossings: int = 1,
                min_excursion: int = 1) -> EdgePoints:
    """Dwells at count edges of a quantised displacement x (m or rad, shape (n,)) with force (shape (n,)).

    A change of one step between samples j and j+1 puts the true displacement on the boundary
    (x[j] + x[j+1])/2 within [t_j, t_j+1]. Consecutive changes across the same boundary, at most ``gap``
    samples apart, form one dwell; its force is the mean over the samples it spans (the position loop's
    J*x'' averages out over a dwell). Changes of more than one step are skipped (the path between is not
    pinned).

    Two successive dwells at the same edge mean the path went past it and turned back inside the next
    count: a turning point no edge pins. It is inserted between them with the extreme of the force over the
    excursion (a 21-sample moving average) and a displacement b +- e, e = (F_extreme - F_b)/slope from the
    two dwells before, within [0, step] (half a step when there is no usable slope); ``crossings`` is 0 there."""
    x, force = np.asarray(x, float), np.asarray(force, float)
    dx = np.diff(x)
    j = np.nonzero((dx != 0) & (np.abs(dx) < 1.5 * step))[0]
    b = 0.5 * (x[j] + x[j + 1])
    rest = force[: max(1, min(REST_SAMPLES, int(j[0]) + 1 if j.size else x.size))].mean()
    xs, fs, first, last, count = [float(x[0])], [float(rest)], [0], [0], [0]
    start = 0
    for i in range(1, j.size + 1):
        same = i < j.size and abs(b[i] - b[start]) < 0.25 * step and j[i] - j[i - 1] <= gap
        if same:
            continue
        a, z = int(j[start]), int(j[i - 1]) + 1
        xs.append(float(b[start]))
        fs.append(float(force[a: z + 1].mean()))
        first.append(a)
        last.append(z)
        count.append(i - start)
        start = i
    e = _with_excursions(x, force, step, EdgePoints(np.array(xs), np.array(fs), np.array(first), np.array(last),
                                                    np.array(count)), min_excursion)
    keep = (e.crossings == 0) | (e.crossings >= min_crossings)
    return EdgePoints(e.x[keep], e.force[keep], e.first[keep], e.last[keep], e.crossings[keep])


def _with_excursions(x: np.ndarray, force: np.ndarray, step: float, e: EdgePoints, min_excursion: int) -> EdgePoints:
    from scipy.ndimage import uniform_filter1d

    smooth = uniform_filter1d(force, EXTREME_SMOOTHING, mode="nearest")
    rows = [(e.x[0], e.force[0], e.first[0], e.last[0], e.crossings[0])]
    for i in range(1, e.size):
        prev = rows[-1]
        if i > 1 and e.x[i] == e.x[i - 1] and e.last[i - 1] + min_excursion < e.first[i]:
            a, z = int(e.last[i - 1]) + 1, int(e.first[i])
            side = float(np.sign(x[(a + z) // 2] - e.x[i]))
            extreme = float(smooth[a:z].max() if side > 0 else smooth[a:z].min())
            depth = 0.5 * step
            if len(rows) > 1 and rows[-2][0] != prev[0]:
                slope = (prev[1] - rows[-2][1]) / (prev[0] - rows[-2][0])
                if slope * side > 0:
                    depth = float(np.clip((extreme - prev[1]) / slope * side, 0.0, step))
            rows.append((e.x[i] + side * depth, extreme, a, z - 1, 0))
        rows.append((e.x[i], e.force[i], e.first[i], e.last[i], e.crossings[i]))
    cols = list(zip(*rows, strict=True))
    return EdgePoints(*(np.array(c) for c in cols))
