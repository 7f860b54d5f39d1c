"""One way to score a model on data: :func:`score` (arrays) and :func:`score_chunks` (a record read chunk by chunk).

Every door that reports an error figure of a friction model on a run (``hilbench identify``, ``compare``'s rows,
``residual``'s start and final model, the campaign steps and the GUI, which call those doors) scores it here, so
the same model on the same data gives the same figure everywhere (docs/metrics.md, "Scoring held-out data").

The model is a :class:`firmware_sim.engine.plant.PlantParams` (torque_constant 1: the input is the torque). Every
door can give one: ``FrictionModel.plant_params()`` (identify), a family's plant (compare),
``residual.simulation_error.plant_params(fit)`` (the residual loop). A predict-callable would let each door keep
its own prediction, which is exactly how the figures drifted apart; the plant is the one engine every model is
simulated with, and its friction along an imposed path (``Plant.friction_path``) covers every family (Maxwell-slip
elements, Coulomb/Stribeck, LuGre, GMS, the continuous hysteresis, tables, cogging and spring beside it).

The data: the measured position x (rad or m) and torque tau (N*m or N, sample timing ``timing``, see
``identification.regressors.held_torque``) of one run, shape (n,), sampled at fs Hz, and the span
``[start, stop)`` that is scored. Samples before ``start`` are the run before a held-out tail: the model's
friction state runs along them and nothing there is scored. A separate validation run is scored from its own
first sample (relaxed elements, bristles at rest), as the run itself starts.

Figures (fractions; texts show them in percent):

- **torque NRMSE** (``torque_nrmse``), the equation error. L is the zero-phase Butterworth low-pass of
  ``identification.regressors`` (cutoff fs/20, order 4 by default), D the central difference, T the triangle
  average ``(y[k-1] + 10 y[k] + y[k+1])/12``; rows are every ``decimation``-th sample (fs/(2.5 cutoff)) from
  ``edge`` to ``n - edge`` on the run's own index (``regressors.edge_samples``), those in the span scored::

      e[r] = L[tau_a](r) - ( J D^2 L[x](r) + b(v) v(r) + T L[F + K x + C(x)](r) ),   v = D L[x]
      torque_nrmse = rms(e) / std(L[tau_m])

  with tau_m the measured torque aligned at the samples (``regressors.torque_at_samples``), tau_a the torque the
  model says acts (the plant's input chain: delay, current lag, torque-constant error, plus its offset
  ``torque_offset`` = -c0 and drift, aligned the same way), F the model's friction along the measured path from
  the run's first sample (``Plant.friction_path``, viscous part apart), K the spring, C the cogging.
  For the linear-in-parameters Maxwell-slip model this is, term by term, the regression of ``maxwell_fit``.
  Beside it the **relative error** ``torque_rel_pct`` = 100 |e| / |L[tau_m]| (the EMPS metric). A
  displacement-driven record gives the same error as the **force NRMSE** (``force_nrmse``) and ``force_rel_pct``.
- **position NRMSE** (``position_nrmse``): rms(x - x_sim)/std(x) over the span, the open-loop simulation of the
  plant under the torque from the span's first sample; **segmented** (``position_nrmse_segmented``, and
  ``position_rms_segmented`` in rad or m) when it restarts every ``segment`` s, the restarts at
  ``start + j * round(segment * fs)``. Each (re)start takes the measured state: the path's position (the
  measured one low-passed lightly, at 8x the cutoff and at most 0.4 fs, so that encoder steps larger than a
  presliding distance do not drive the friction state), the velocity D L[x](k0) of the whole run, and the friction
  state (element deflections, bristles, the hysteresis stack) that path has left at k0 since the run's first
  sample; the friction F of the torque figure follows the same path and velocity. The plant is integrated with RK4
  sub-steps that keep the stiffest mode at 80 % of the stability radius.

Why the initial state matters: a Maxwell-slip element started relaxed at the first sample of a held-out tail
carries no deflection, while inside the run it carries the deflection the path left; the predicted friction then
differs by up to k_i*Delta_i until the path has travelled 2*Delta_i, and the figure of the same model on the same
samples differs between a tail cut out of a run and the same span inside it (validation torque NRMSE 5.06 %
against 0.64 % on the 30 % tail of a 3 s DC-motor run at 2 kHz, docs/metrics.md). Here both are the span inside
the run, to rounding (tests/analysis/test_scoring.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.chunked import BLOCK, ChunkSource, array_chunks, default_margin, windows
from hilbench.analysis.identification.regressors import (
    edge_samples,
    held_torque,
    triangle_average,
    zero_phase_lowpass,
)
from hilbench.common.metrics import SEGMENT_S, RunningNrmse

#: more RK4 sub-steps per sample than this means a model too stiff to simulate at the rate (compare refused it there)
MAX_SUBSTEPS = 2000
#: the friction state follows the measured path low-passed at PATH_FACTOR x the cutoff, at most
#: PATH_NYQUIST_FRACTION x fs (the residual loop's ``velocity_fast``; None in ScoreSettings: the raw samples)
PATH_FACTOR = 8.0
PATH_NYQUIST_FRACTION = 0.4


@dataclass(frozen=True)
class ScoreSettings:
    """How a model is scored. ``cutoff`` (Hz; None: fs/20), ``order`` and ``decimation`` (rows kept; None:
    fs/(2.5 cutoff)) of the equation error; ``segment`` (s) between restarts of the segmented simulation;
    ``force``: a displacement-driven record (force figures, no simulation); ``simulate``: the position figures."""

    cutoff: float | None = None
    order: int = 4
    decimation: int | None = None
    segment: float = SEGMENT_S
    force: bool = False
    simulate: bool = True
    path_factor: float | None = PATH_FACTOR

    def resolved(self, fs: float) -> tuple[float, int]:
        """(cutoff Hz, decimation) at ``fs`` Hz."""
        cutoff = float(self.cutoff) if self.cutoff is not None else fs / 20.0
        dec = int(self.decimation) if self.decimation is not None else max(1, int(fs / (2.5 * cutoff)))
        return cutoff, max(1, dec)


@dataclass
class Score:
    """The figures (``figures``, fractions and counts) and, from :func:`score`, the arrays behind them: the scored
    rows (``rows``, indices into the arrays given), L[tau_m] (``measured``) and the model's L[tau] at them
    (``predicted``, = measured - e), and the simulated positions over the span (``position_sim``, open loop;
    ``position_sim_segmented``), shape (stop - start,)."""

    figures: dict
    rows: np.ndarray = field(default_factory=lambda: np.empty(0, int))
    measured: np.ndarray = field(default_factory=lambda: np.empty(0))
    predicted: np.ndarray = field(default_factory=lambda: np.empty(0))
    position_sim: np.ndarray | None = None
    position_sim_segmented: np.ndarray | None = None

    def prefixed(self, prefix: str, drop: tuple[str, ...] = ()) -> dict:
        """The figures as ``{prefix}_{name}`` (``train_torque_nrmse``, ``validation_position_nrmse``...), less
        those named in ``drop``."""
        return {f"{prefix}_{k}": v for k, v in self.figures.items() if k not in drop}


@dataclass
class ScoredRun:
    """A run as :func:`score` reads it: position and torque of the whole run so far, shape (n,), and ``start``,
    the first sample of the scored span (the samples before it are a held-out tail's lead)."""

    position: np.ndarray
    torque: np.ndarray
    fs: float
    timing: str = "hold_next"
    start: int = 0


def scored_run(record) -> ScoredRun:
    """A :class:`hilbench.analysis.record.Record` as :func:`score` reads it: its lead (a held-out tail's run before
    it, ``record_split``) joined before its samples, the span its own samples."""
    x, tau = np.asarray(record.position, float), np.asarray(record.torque, float)
    lead = getattr(record, "lead", None)
    if lead is None:
        return ScoredRun(x, tau, float(record.sample_rate), record.timing, 0)
    return ScoredRun(np.concatenate([lead[0], x]), np.concatenate([lead[1], tau]), float(record.sample_rate),
                     record.timing, int(np.asarray(lead[0]).size))


def score_run(params, run: ScoredRun, settings: ScoreSettings | None = None, *, keep: bool = False) -> Score:
    """:func:`score` of ``params`` on a :class:`ScoredRun` (its span to its end)."""
    return score(params, run.position, run.torque, run.fs, timing=run.timing, start=run.start, settings=settings,
                 keep=keep)


def substeps(params, fs: float) -> int:
    """RK4 sub-steps per sample keeping the stiffest mode at 80 % of the engine's stability radius."""
    from hilbench.firmware_sim.engine.plant import RK4_STABLE_RADIUS, stiffest_eigenvalue

    try:
        lam = stiffest_eigenvalue(params)
    except ValueError as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    sub = max(1, math.ceil(lam / fs / (0.8 * RK4_STABLE_RADIUS)))
    if sub > MAX_SUBSTEPS:
        raise AnalysisError(f"model cannot be simulated: its stiffest mode ({lam:.3g} 1/s) needs {sub} RK4 "
                            f"sub-steps per sample (limit {MAX_SUBSTEPS}); an element is implausibly stiff")
    return sub


def score(params, position: np.ndarray, torque: np.ndarray, fs: float, *, timing: str = "hold_next",
          start: int = 0, stop: int | None = None, settings: ScoreSettings | None = None,
          keep: bool = False) -> Score:
    """Score the model ``params`` (PlantParams, torque_constant 1) on samples ``[start, stop)`` of one run.

    Args:
        position: measured path, shape (n,), rad or m, from the run's first sample.
        torque: measured torque or force, shape (n,), N*m or N, sample timing ``timing``.
        fs: sampling rate, Hz.
        start, stop: the scored span (samples; ``stop`` None: n). Before ``start`` the friction state runs along
            the measured path and nothing is scored.
        keep: also return the arrays (rows, L[tau], prediction, simulated positions of the span).
    Returns:
        :class:`Score`; figures (module docstring): ``torque_nrmse`` and ``torque_rel_pct`` (or ``force_nrmse`` and
        ``force_rel_pct``),
        ``position_nrmse``, ``position_nrmse_segmented``, ``position_rms_segmented`` (rad or m), ``samples``.
    """
    x = np.asarray(position, float)
    tau = np.asarray(torque, float)
    if x.shape != tau.shape or x.ndim != 1:
        raise AnalysisError(f"position and torque must be 1-D of equal length, got {x.shape} and {tau.shape}")
    return score_chunks(params, array_chunks(x, tau), fs, timing=timing, start=start, stop=stop, settings=settings,
                        keep=keep, n=x.size)


#: what a constant reference's one-line refusal adds: the figure is over the scored span only
SPAN = " over the scored span"


def _mechanics(params):
    """(plant of the mechanics and friction alone, the same without viscous friction): the input chain (delay, lag,
    torque-constant error, offset, drift) is applied to the torque instead, which is exact in current mode (the
    chain does not depend on the motion)."""
    mech = params.replace(delay_samples=0, current_lag=0.0, torque_constant_error=0.0, torque_offset=0.0,
                          torque_drift=0.0, torque_constant=1.0, noise_current=0.0, noise_position=0.0,
                          counts_per_rev=0, velocity_kp=0.0, velocity_ki=0.0, current_limit=math.inf)
    path = mech.replace(viscous=0.0, viscous_neg=None, spring=0.0, cogging=(),
                        inertia=mech.inertia if mech.inertia > 0 else 1.0)
    return mech, path


def _path_substeps(params, fs: float) -> int:
    """The sub-steps the plant's constructor asks for; ``friction_path`` advances the state by its exact update over
    each sample's displacement and never integrates, so none of them is used (``families.path_plant``)."""
    from hilbench.firmware_sim.engine.plant import RK4_STABLE_RADIUS, stiffest_eigenvalue

    return max(1, math.ceil(stiffest_eigenvalue(params) / fs / RK4_STABLE_RADIUS) + 1)


def _has_chain(params) -> bool:
    return bool(params.delay_samples or params.current_lag or params.torque_constant_error or params.torque_drift
                or params.torque_constant != 1.0)


class _Carried:
    """A stateful per-sample operator over overlapping windows: the state is saved inside the next window
    (``keep``), so every sample is computed once from the state the samples before it left. The friction state is
    resumed ``lag`` samples into the next window, past the start-up transient of the window's own light low-pass of
    the path (``_path_lag``); the samples before it lie in the window's margin and only their filtered tail, e^-39
    of it, reaches a scored row."""

    def __init__(self, plant):
        self.plant = plant
        self.resume = 0  # the run's sample the saved state belongs to

    def friction(self, x: np.ndarray, v: np.ndarray, wa: int, keep: int | None, marks: list[int]
                 ) -> tuple[np.ndarray, dict]:
        """Friction along the window's path (window starting at the run's sample ``wa``); the plant state at each
        of ``marks`` (window indices, increasing) and at ``keep`` (saved for the next window)."""
        out = np.empty(x.size)
        states: dict[int, bytes] = {}
        lo = self.resume - wa
        cuts = sorted({c for c in [*marks, *([keep] if keep is not None else [])] if c >= lo})
        saved = None
        for c in [*cuts, x.size - 1]:
            out[lo : c + 1] = self.plant.friction_path(x[lo : c + 1], v[lo : c + 1])
            state = self.plant.get_state()
            if c in marks:
                states[c] = state
            if c == keep:
                saved = state
            lo = c
        out[: self.resume - wa] = out[self.resume - wa]
        if keep is not None:
            self.plant.set_state(saved)
            self.resume = wa + keep
        return out, states

    def chain(self, u: np.ndarray, keep: int | None) -> np.ndarray:
        """The torque acting (the plant's input chain) for the window's held inputs."""
        if keep is None:
            return self.plant.run(u).torque
        first = self.plant.run(u[:keep]).torque
        saved = self.plant.get_state()
        rest = self.plant.run(u[keep:]).torque
        self.plant.set_state(saved)
        return np.concatenate([first, rest])


def _aligned(h: np.ndarray) -> np.ndarray:
    """``regressors.torque_at_samples`` of held values h: h[0], then (h[k-1] + h[k])/2."""
    return np.concatenate([h[:1], 0.5 * (h[:-1] + h[1:])])


def _cogging(params, x: np.ndarray) -> np.ndarray:
    out = np.zeros_like(x)
    for c in params.cogging:
        out += c.amplitude * np.sin(c.order * x + c.phase)
    return out


def _viscous(params, v: np.ndarray) -> np.ndarray:
    neg = params.viscous if params.viscous_neg is None else params.viscous_neg
    return np.where(v >= 0.0, params.viscous, neg) * v


def score_chunks(params, source: ChunkSource, fs: float, *, timing: str = "hold_next", start: int = 0,
                 stop: int | None = None, settings: ScoreSettings | None = None, keep: bool = False,
                 n: int | None = None, block: int = BLOCK) -> Score:
    """:func:`score` on a run read chunk by chunk (``identification.chunked``: a callable returning a fresh iterator
    of ``(position, torque)`` pairs); memory is bounded by the block, whatever the run's length (the filter's
    start-up transient inside a window is e^-40 of the signal, ``chunked``'s margin). ``n``: the run's length if
    known (else the source is read once more to count it); ``keep`` as :func:`score` (arrays of the span)."""
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    s = settings or ScoreSettings()
    if not (np.isfinite(fs) and fs > 0):
        raise AnalysisError(f"sampling rate must be > 0, got {fs}")
    if n is None:
        n = sum(np.asarray(x).size for x, _ in source())
    stop = n if stop is None else int(stop)
    start = int(start)
    if not 0 <= start < stop <= n:
        raise AnalysisError(f"the scored span {start}:{stop} is not inside the run's {n} samples")
    cutoff, dec = s.resolved(fs)
    if not 0 < cutoff < fs / 2:
        raise AnalysisError(f"filter cutoff {cutoff} Hz must be in (0, {fs / 2}) Hz (Nyquist)")
    path_cutoff = None if s.path_factor is None else min(s.path_factor * cutoff, PATH_NYQUIST_FRACTION * fs)
    # the friction state is resumed past the start-up transient of the path's low-pass (40 of its time constants)
    lag = 0 if path_cutoff is None else 4 * edge_samples(fs, path_cutoff)
    edge = edge_samples(fs, cutoff)
    lo_row = max(edge, start)
    lo_row += (-(lo_row - edge)) % dec
    hi_row = min(stop, n - edge)
    if len(range(lo_row, hi_row, dec)) < 10:
        raise AnalysisError(f"too short to score: samples {start}:{stop} of {n} leave "
                            f"{len(range(lo_row, hi_row, dec))} rows after the filter's start-up ({edge} samples "
                            f"at each end of the run, cutoff {cutoff:g} Hz)")
    dt = 1.0 / fs
    mech, path_params = _mechanics(params)
    seg = max(2, int(round(s.segment * fs))) if s.segment and s.segment > 0 else None
    if seg is None:
        raise AnalysisError(f"segment must be positive, got {s.segment} s")
    simulate = s.simulate and not s.force
    try:
        path = _Carried(Plant(path_params, dt, _path_substeps(path_params, fs)))
        chain = _Carried(Plant(params.replace(**_CHAIN_ONLY), dt, 1)) if _has_chain(params) else None
        sub = substeps(mech, fs) if simulate else 1
    except PlantParameterError as exc:
        raise AnalysisError(f"model cannot be scored: {exc}") from None
    offset = float(params.torque_offset)
    margin = max(default_margin(fs, cutoff), 2 * lag, 2)
    torque_sums, whole, segmented = RunningNrmse(), RunningNrmse(), RunningNrmse()
    kept: dict[str, list[np.ndarray]] = {"rows": [], "measured": [], "predicted": [], "sim": [], "seg": []}
    sims: dict[str, object] = {"whole": None, "seg": None}
    try:
        for w in windows(source, block, margin):
            nxt = None if (w.n is not None and w.b >= w.n) else w.b - margin - w.wa  # next window's start
            x = w.x
            h = held_torque(w.tau, timing)  # the window's last value needs the next sample: in the margin
            xf = zero_phase_lowpass(x, fs, cutoff, s.order)
            v = np.gradient(xf, dt) if xf.size > 1 else np.zeros_like(xf)
            acting = chain.chain(h / params.torque_constant, nxt) if chain is not None else h + offset
            # restarts of the simulations inside this block (window indices)
            a, b = max(w.a, start), min(w.b, stop)
            marks = []
            if simulate and a < b:
                first = a + (-(a - start)) % seg
                marks = [k - w.wa for k in range(first, b, seg)]
            # the path the friction state follows (module docstring): lightly low-passed, or the measured samples;
            # the velocity the laws read (sign, Stribeck, a restart) is the regression's, D L[x]: the light
            # low-pass's own derivative carries the encoder's noise (at 10 kHz, 4 kHz of it)
            xp = x if path_cutoff is None else zero_phase_lowpass(x, fs, path_cutoff, s.order)
            friction, states = path.friction(xp, v, w.wa, None if nxt is None else nxt + lag, marks)
            total = friction + mech.spring * xp + _cogging(mech, xp)
            # aligned at the samples per window, as chunked.blocks does: a window's first sample lies in its margin
            tau_m, tau_a = _aligned(h), _aligned(acting)
            both = zero_phase_lowpass(np.vstack([tau_m, tau_a, total]), fs, cutoff,
                                      s.order)
            hi = min(w.b, hi_row)
            first_row = max(lo_row, w.a)
            first_row += (-(first_row - lo_row)) % dec
            rows = np.arange(first_row, hi, dec)
            if rows.size:
                loc = rows - w.wa
                acc = (xf[loc + 1] - 2.0 * xf[loc] + xf[loc - 1]) / dt**2
                pred = mech.inertia * acc + _viscous(mech, v[loc]) + triangle_average(both[2], loc)
                meas, act = both[0][loc], both[1][loc]
                err = act - pred
                torque_sums.add(meas, err)
                if keep:
                    kept["rows"].append(rows)
                    kept["measured"].append(meas)
                    kept["predicted"].append(meas - err)
            if simulate and a < b:
                u = acting  # the acting torque, held over each sample (input of the plant without its chain)
                lo_l, hi_l = a - w.wa, b - w.wa
                for name, sums, restarts in (("whole", whole, [start - w.wa] if w.a <= start < w.b else []),
                                             ("seg", segmented, marks)):
                    out = np.empty(hi_l - lo_l)
                    pos = lo_l
                    for k0 in [*restarts, hi_l]:
                        if k0 > pos and sims[name] is not None:
                            out[pos - lo_l : k0 - lo_l] = sims[name].run(u[pos:k0]).theta
                        if k0 < hi_l:
                            plant = Plant(mech, dt, sub, theta0=float(xp[k0]), omega0=float(v[k0]))
                            plant.set_state(states[k0])
                            sims[name] = plant
                        pos = k0
                    sums.add(x[lo_l:hi_l], x[lo_l:hi_l] - out)
                    if keep:
                        kept["sim" if name == "whole" else "seg"].append(out)
    except (PlantParameterError, FloatingPointError) as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    figures: dict = {}
    if s.force:
        figures["force_nrmse"] = torque_sums.nrmse(SPAN)
        figures["force_rel_pct"] = 100.0 * torque_sums.relative()
    else:
        figures["torque_nrmse"] = torque_sums.nrmse(SPAN)
        figures["torque_rel_pct"] = 100.0 * torque_sums.relative()
        if simulate:
            figures["position_nrmse"] = whole.nrmse(SPAN)
            figures["position_nrmse_segmented"] = segmented.nrmse(SPAN)
            figures["position_rms_segmented"] = float(math.sqrt(segmented.e2 / segmented.n))
    figures["samples"] = int(stop - start)
    out = Score(figures)
    if keep:
        cat = {k: np.concatenate(v) if v else None for k, v in kept.items()}
        out.rows, out.measured, out.predicted = cat["rows"], cat["measured"], cat["predicted"]
        out.position_sim, out.position_sim_segmented = cat["sim"], cat["seg"]
    return out


#: the plant reduced to its input chain (its torque output is the torque acting; nothing of the motion matters)
_CHAIN_ONLY = {"inertia": 1.0, "spring": 0.0, "ms_stiffness": (), "ms_slip": (), "viscous": 0.0, "viscous_neg": None,
               "coulomb": 0.0, "coulomb_neg": None, "static": None, "stribeck_velocity": 0.0, "cogging": (),
               "restoring_table": None, "damping_table": None, "lugre": None, "gms": None, "hysteresis": None,
               "noise_current": 0.0, "noise_position": 0.0, "counts_per_rev": 0, "velocity_kp": 0.0,
               "velocity_ki": 0.0, "current_limit": math.inf}
