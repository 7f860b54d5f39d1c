"""Experiments sized from the motor: a break-away probe on the device, then a campaign sized from what it showed.

    plan = plan_experiments("sim://", DeviceSettings(current_limit=20.0), probe_dir="plan-probe")
    print("\\n".join(plan.lines()))
    plan.write("plan.toml")            # hilbench campaign plan.toml plays it as is

The probe (:mod:`~bench.acquisition.breakaway_probe`) is played through the ordinary runner, so its run files are
kept like any
other. Its peak current starts at a fifth of the current limit and grows by half until the motor slides both
ways with a peak at least :data:`PEAK_OVER_BREAKAWAY` times its break-away (long enough slides for the fit of
the sliding current, J and b), never above :data:`LIMIT_SHARE` of the current limit.

Sizing (every current at most :data:`LIMIT_SHARE` of the current limit; ``I_s`` is the larger sliding current of
the two directions, ``x_p`` the presliding distance x_p(0.9)):

- identification: the random-enveloped input's quiet half-periods stay within ``QUIET_SHARE * I_s`` (presliding),
  its loud half-periods are scaled, on the very input the protocol will play (same seed, rate and length), until
  at least :data:`SLIDE_SHARE` of all samples drive above ``1.1 * I_s`` in each direction. The noise is
  normalised to its peak, so how much of it lies above a level depends on the seed and the length: the amplitude
  is found on the input itself, not from a rule of thumb;
- stepped sine: amplitudes ``STEP_FACTORS * I_s``, from presliding to gross sliding;
- chirp: a log sweep at ``CHIRP_GAIN * I_s``, whose sliding displacement amplitude falls as 1/f^2 (Den Hartog's
  continuous-sliding solution for an inertia under a sine force and Coulomb friction) from
  ``CHIRP_SPAN * x_p`` at the start frequency to ``x_p`` at the stop frequency;
- presliding: nested reversals of 4, 3, 2 and 1 times ``x_p``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from hilbench.bench.acquisition.breakaway_probe import BreakawayProbe, ProbeError, ProbeResult, analyse_probe
from hilbench.bench.acquisition.protocols import Chirp, Identification, Presliding, Protocol, SteppedSine
from hilbench.bench.acquisition.runner import Bench, DeviceSettings, Progress
from hilbench.bench.errors import BenchError

#: Largest share of the current limit any planned current (probe or protocol) reaches.
LIMIT_SHARE = 0.9
#: The probe's first peak, as a share of the current limit, and its growth per try.
FIRST_PEAK_SHARE = 0.2
PEAK_GROWTH = 1.5
#: Peak over break-away the probe needs for slides long enough to fit the sliding current, J and b.
PEAK_OVER_BREAKAWAY = 1.4
QUIET_SHARE = 0.5
SLIDE_SHARE = 0.05
STEP_FACTORS = (0.5, 0.8, 1.25, 2.0)
STEP_FREQUENCIES = (2.0, 5.0, 10.0)  # Hz
CHIRP_GAIN = 1.5
CHIRP_SPAN = 25.0
PRESLIDING_MULTIPLES = (4.0, 3.0, 2.0, 1.0)
#: A load on a spring is probed once more with slow returns and ramps of this many natural periods, so that it
#: follows the current quasi-statically instead of swinging at sqrt(k/J) (its k and J are then within 0.3 % and
#: 3 % on the paper's system, against 7 % and 6 % from the quick-return probe).
SPRING_RAMP_PERIODS = 5.0


class PlanError(BenchError):
    """No plan: the probe found no break-away within the limits, or a protocol cannot be sized."""


@dataclass
class Plan:
    """The probe's findings, the device settings and the sized protocols (campaign run name -> protocol)."""

    device: str
    settings: DeviceSettings
    probe: ProbeResult
    probe_runs: list[str]
    runs: dict[str, Protocol]
    notes: list[str] = field(default_factory=list)  # what was clipped to the limits, said in words

    @property
    def spring_share(self) -> float:
        """The fitted spring's force over the probe's travel, |k/Kt| * travel, as a share of the sliding
        current: about 0 on a load without a spring (a spring load is refused, spring_refusal)."""
        fit = self.probe.sliding or {}
        return abs(fit.get("spring_per_kt", math.nan)) * self.probe.travel / self.sliding_current

    @property
    def sliding_current(self) -> float:
        """The larger sliding current of the two directions, A."""
        fit = self.probe.sliding or {}
        return max(fit["positive"], -fit["negative"])

    def lines(self) -> list[str]:
        """The plan as text, every number with its unit."""
        fit, p = self.probe.sliding or {}, self.probe
        kt = self.settings.torque_constant
        out = [f"probe: {len(self.probe_runs)} run(s), last {p.path} (peak {p.peak:.3g} A)",
               f"  break-away (speed above {p.velocity_threshold:.3g} rad/s): +{p.positive:.4g} A, "
               f"{p.negative:.4g} A",
               f"  sliding current (fit of the slides): +{fit['positive']:.4g} A, {fit['negative']:.4g} A "
               f"({fit['positive'] * kt:.4g} N*m, {fit['negative'] * kt:.4g} N*m at {kt:g} N*m/A)",
               f"  inertia J = {fit['inertia_per_kt'] * kt:.4g} kg*m^2, viscous b = "
               f"{fit['viscous_per_kt'] * kt:.4g} N*m*s/rad, spring k = {fit['spring_per_kt'] * kt:.3g} N*m/rad "
               f"(no restoring force: {100 * self.spring_share:.2g} % of the sliding current over the probe's travel)",
               f"  presliding distance x_p(0.9) = {1e3 * (p.presliding_distance or math.nan):.4g} mrad"]
        for name, proto in self.runs.items():
            out.append(f"{name}: {describe(proto)}")
        out += [f"note: {n}" for n in self.notes]
        return out

    def toml(self) -> str:
        """The campaign file: ``hilbench campaign`` plays it as is."""
        from hilbench.bench.acquisition.campaign_plan import SETTING_UNITS

        head = ["# Sized by `hilbench plan` from a break-away probe:", *[f"#   {line}" for line in self.lines()],
                "", "[defaults]", f"device = {_toml(self.device)}"]
        defaults = DeviceSettings()
        for name, unit in SETTING_UNITS.items():
            value = getattr(self.settings, name)
            if value != getattr(defaults, name) and math.isfinite(value):
                head.append(f"{name} = {_quantity(value, unit)}")
        inertia = (self.probe.sliding or {}).get("inertia_per_kt", math.nan) * self.settings.torque_constant
        if math.isfinite(inertia) and inertia > 0:  # read by the skeleton step (the run files' calibration)
            head += ["", "# what the probe measured of the load, written into every run file's calibration",
                     "[plant]", f"inertia = {_quantity(inertia, 'kg*m^2')}"]
        for name, proto in self.runs.items():
            head += ["", "[[run]]", f"name = {_toml(name)}", f"protocol = {_toml(proto.name)}"]
            for key, spec in proto.specs().items():
                if key in unused_parameters(proto):
                    continue
                value = getattr(proto, key)
                unit = spec.unit_for(proto.mode) if spec.unit not in ("", "unit", "periods") else None
                if unit is not None and "unit" in unit:  # presliding's rate: in its `unit`, a plain number
                    unit = None
                if spec.kind in ("int", "choice", "str") or unit is None:
                    head.append(f"{key} = {_toml(value)}")
                else:
                    head.append(f"{key} = {_quantity(value, unit)}")
        return "\n".join(head) + "\n"

    def write(self, path: str | Path) -> None:
        from hilbench.bench.storage.outputs import write_text

        write_text(path, self.toml())


def unused_parameters(proto: Protocol) -> set[str]:
    """Parameters the protocol as planned does not play (a log chirp's quadratic rate, m_per_rad of a run not
    in metres): a campaign file leaves them out rather than write a placeholder."""
    if isinstance(proto, Chirp):
        return {"rate"} if proto.sweep != "quadratic" else {"f_start", "f_stop"}
    if isinstance(proto, Presliding):
        return ({"m_per_rad"} if proto.unit != "m" else set()) | ({"inertia"} if proto.inertia == 0 else set())
    return set()


def describe(proto: Protocol) -> str:
    """A planned protocol in one line, units named."""
    if isinstance(proto, Identification):
        return (f"identification {proto.duration:g} s at {proto.sample_rate} Hz, envelope amplitude "
                f"{proto.amplitude:.4g} A, offset {proto.offset:.4g} A (quiet {proto.offset - proto.amplitude:.3g} A,"
                f" loud {proto.offset + proto.amplitude:.3g} A), seed {proto.seed}")
    if isinstance(proto, SteppedSine):
        return (f"stepped sine at {', '.join(f'{a:.3g}' for a in proto.amplitudes)} A x "
                f"{', '.join(f'{f:g}' for f in proto.frequencies)} Hz")
    if isinstance(proto, Chirp):
        return (f"chirp ({proto.sweep}) {proto.gain:.4g} A from {proto.f_start:.3g} to {proto.f_stop:.3g} Hz in "
                f"{proto.duration:g} s")
    if isinstance(proto, Presliding):
        return (f"presliding reversals at {', '.join(f'{a:g}' for a in proto.amplitudes)} x "
                f"{1e3 * proto.presliding_distance:.4g} mrad, {proto.rate:g} x_p/s")
    return proto.name


def _toml(value: object) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


def _quantity(value: object, unit: str) -> str:
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_quantity(v, unit) for v in value) + "]"
    return _toml(f"{float(value):.6g} {unit}")  # type: ignore[arg-type]


def probe_breakaway(bench: Bench, probe_dir: str | Path, *, sample_rate: int = 10000, overwrite: bool = False,
                    progress: Callable[[Progress], None] | None = None,
                    on_probe: Callable[[ProbeResult], None] | None = None) -> tuple[ProbeResult, list[str]]:
    """Play probes of growing peak current until the motor slid both ways with slides long enough to fit;
    returns the last probe's result and the run files played (``probe_dir/probe-N.h5``)."""
    cap = LIMIT_SHARE * bench.settings.current_limit
    peak = FIRST_PEAK_SHARE * bench.settings.current_limit
    played: list[str] = []
    while True:
        path = Path(probe_dir) / f"probe-{len(played) + 1}.h5"
        result = bench.run(BreakawayProbe(peak=peak, sample_rate=sample_rate), path, overwrite=overwrite,
                           progress=progress, operator="hilbench plan")
        played.append(str(result.path))
        if result.status != "completed":
            raise PlanError(f"the probe {result.path} ended {result.status}: {result.message}")
        try:
            found = analyse_probe(str(result.path))
        except ProbeError as exc:
            if "still moves" not in str(exc):
                raise
            raise PlanError(f"{exc}. A heavy free-sliding load: lower --current-limit (the probe's peaks stay "
                            f"within {LIMIT_SHARE:g} of it)") from None
        if on_probe is not None:
            on_probe(found)
        if found.spring:
            if found.return_time < found.ramp_time:  # measure k and J once more without the quick release's swing
                inertia, k = (found.sliding["inertia_per_kt"], found.sliding["spring_per_kt"])  # type: ignore
                period = 2 * math.pi * math.sqrt(inertia / k) if inertia > 0 and k > 0 else 1.0
                ramp = min(60.0, max(1.5, SPRING_RAMP_PERIODS * period))
                slow = BreakawayProbe(peak=peak, ramp_time=ramp, return_time=ramp, hold=min(10.0, max(0.3, period)),
                                      sample_rate=sample_rate)
                path = Path(probe_dir) / f"probe-{len(played) + 1}.h5"
                result = bench.run(slow, path, overwrite=overwrite, progress=progress, operator="hilbench plan")
                played.append(str(result.path))
                if result.status != "completed":
                    raise PlanError(f"the probe {result.path} ended {result.status}: {result.message}")
                again = analyse_probe(str(result.path))
                if on_probe is not None:
                    on_probe(again)
                if again.spring:  # (too slow to pass the speed threshold on a small peak: the first stands)
                    found = again
            raise PlanError(spring_refusal(found, bench.settings.torque_constant))
        slid = found.positive is not None and found.negative is not None
        breakaway = max(abs(found.positive), abs(found.negative)) if slid else 0.0  # type: ignore[arg-type]
        long_enough = found.peak >= PEAK_OVER_BREAKAWAY * breakaway or found.peak >= cap
        if slid and long_enough and found.sliding is not None and found.presliding_distance is not None:
            return found, played
        if peak >= cap:
            what = "slid both ways" if not slid else "slid long enough to fit its sliding current"
            raise PlanError(f"the motor never {what} up to {peak:.3g} A ({LIMIT_SHARE:g} of --current-limit "
                            f"{bench.settings.current_limit:g} A); raise --current-limit if the motor allows it")
        peak = min(cap, max(peak * PEAK_GROWTH, PEAK_OVER_BREAKAWAY * breakaway * 1.05))


def spring_refusal(found: ProbeResult, torque_constant: float) -> str:
    """One line: the spring and inertia the probe measured on a load on a spring, and why plan stops there.

    The friction of a spring load is what the current leaves after the spring force k*x over the probe's travel.
    With the paper's system (k = 50 N*m/rad, friction level 1.64 N*m) the spring carries about 270 N*m at the end
    of a slide long enough to saturate the friction, so a 0.2 % error of the fitted k (the presliding stiffness
    the least squares of the slides cannot separate from the spring) is 40 % of the friction: too small a
    difference to size a campaign from."""
    fit = found.sliding or {}
    k = fit.get("spring_per_kt", math.nan) * torque_constant
    inertia = fit.get("inertia_per_kt", math.nan) * torque_constant
    f_n = math.sqrt(k / inertia) / (2 * math.pi) if k > 0 and inertia > 0 else math.nan
    ends = [abs(e) for e in found.breakaway if e is not None]
    share = max(ends) * torque_constant / (k * (found.half_travel or math.nan)) if ends else math.nan
    return (f"{found.path}: a load on a spring: k = {k:.4g} N*m/rad, J = {inertia:.4g} kg*m^2 (natural frequency "
            f"{f_n:.3g} Hz) by the least squares of the probe; its friction at the slides' ends is about "
            f"{100 * share:.2g} % of the spring force there, too small a difference for the break-away probe to "
            f"size friction experiments from. plan sizes loads without a spring; write this campaign by hand "
            f"(docs/cli.md, 'hilbench plan': loads on a spring)")


def size_protocols(probe: ProbeResult, settings: DeviceSettings, *, sample_rate: int = 10000,
                   duration: float = 20.0, seed: int = 0) -> tuple[dict[str, Protocol], list[str]]:
    """The campaign's protocols sized from ``probe`` (see the module docstring), and notes on what the limits
    clipped."""
    if probe.sliding is None or probe.presliding_distance is None:
        raise PlanError(f"{probe.path}: the probe did not slide long enough both ways to size a plan")
    fit = probe.sliding
    level = max(fit["positive"], -fit["negative"])
    cap = LIMIT_SHARE * settings.current_limit
    notes: list[str] = []

    def clipped(value: float, what: str) -> float:
        if value > cap:
            notes.append(f"{what} {value:.3g} A clipped to {cap:.3g} A ({LIMIT_SHARE:g} of the current limit)")
            return cap
        return value

    runs: dict[str, Protocol] = {}
    runs["identification"] = _identification(level, cap, sample_rate, duration, seed, notes)
    steps = tuple(sorted({round(clipped(f * level, f"stepped-sine amplitude {f:g} x sliding current"), 6)
                          for f in STEP_FACTORS}))
    runs["stepped_sine"] = SteppedSine(frequencies=STEP_FREQUENCIES, amplitudes=steps, settle_periods=3,
                                       measure_periods=5, sample_rate=sample_rate)
    runs["chirp"] = _chirp(probe, settings, level, clipped, sample_rate, duration)
    inertia = fit["inertia_per_kt"] * settings.torque_constant  # J*acceleration comes off the presliding force
    runs["presliding"] = Presliding(amplitudes=PRESLIDING_MULTIPLES, unit="d",
                                    presliding_distance=probe.presliding_distance, sample_rate=sample_rate,
                                    inertia=round(inertia, 9) if 0 < inertia <= 100 else 0.0)
    return runs, notes


def _identification(level: float, cap: float, sample_rate: int, duration: float, seed: int,
                    notes: list[str]) -> Identification:
    """Quiet half-periods at QUIET_SHARE of the sliding current; loud ones grown on the played input until
    SLIDE_SHARE of the samples drive past 1.1 x the sliding current each way (bisection, 40 halvings)."""
    from hilbench.bench.acquisition.excitations import lowpass_uniform_noise, rectangular_envelope

    quiet = QUIET_SHARE * level
    base = Identification(duration=duration, amplitude=1.0, offset=0.0, seed=seed, sample_rate=sample_rate)
    # The played input is noise * (offset + amplitude * square), i.e. loud * a + quiet * b with a and b below:
    # linear in the loud level, so the search scales two arrays instead of regenerating the input.
    n = base.n_samples
    noise = lowpass_uniform_noise(n, sample_rate, base.cutoff, seed)
    square = rectangular_envelope(np.arange(n) / sample_rate, 1.0, base.period)
    a, b = noise * (1 + square) / 2, noise * (1 - square) / 2

    def share(loud: float) -> float:
        u = loud * a + quiet * b
        return float(min(np.mean(u > 1.1 * level), np.mean(u < -1.1 * level)))

    def peak(loud: float) -> float:
        return float(np.max(np.abs(loud * a + quiet * b)))

    lo, hi = quiet, quiet
    while peak(hi * 2) <= cap and hi < 1e3:
        hi *= 2
    hi *= 2  # the peak of `hi` is above the cap: the largest loud level within it lies in [lo, hi]
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if peak(mid) <= cap else (lo, mid)
    loud = lo
    if share(loud) < SLIDE_SHARE:
        notes.append(f"identification: within the current limit only {100 * share(loud):.2g} % of the samples "
                     f"slide each way (aim {100 * SLIDE_SHARE:g} %); raise --current-limit for a stronger input")
    else:  # the smallest loud level that slides enough: no harder on the motor than it needs
        lo = quiet
        for _ in range(40):
            mid = (lo + loud) / 2
            lo, loud = (lo, mid) if share(mid) >= SLIDE_SHARE else (mid, loud)
    planned = replace(base, amplitude=(loud - quiet) / 2, offset=(loud + quiet) / 2)
    return planned


def _chirp(probe: ProbeResult, settings: DeviceSettings, level: float, clipped: Callable[[float, str], float],
           sample_rate: int, duration: float) -> Chirp:
    """Log sweep at CHIRP_GAIN x the sliding current. Continuous sliding of an inertia J under a sine force F0
    against Coulomb friction Fc has the displacement amplitude X = F0/(J w^2) * sqrt(1 - (4 Fc / (pi F0))^2)
    (Den Hartog 1931): the sweep starts where X = CHIRP_SPAN * x_p and stops where X = x_p."""
    fit = probe.sliding or {}
    gain = clipped(CHIRP_GAIN * level, f"chirp gain {CHIRP_GAIN:g} x sliding current")
    inertia = fit["inertia_per_kt"] * settings.torque_constant
    if not inertia > 0:
        raise PlanError(f"{probe.path}: the fit of the slides gives no positive inertia ({inertia:.3g} kg*m^2); "
                        f"the slides were too short or too noisy to size a chirp")
    force, friction = gain * settings.torque_constant, level * settings.torque_constant
    sliding = force / inertia * math.sqrt(max(0.0, 1 - (4 * friction / (math.pi * force)) ** 2))  # X * w^2
    x_p = probe.presliding_distance or math.nan

    def frequency(amplitude: float) -> float:
        return math.sqrt(sliding / amplitude) / (2 * math.pi)

    f_stop = min(frequency(x_p), sample_rate / 20)
    f_start = frequency(CHIRP_SPAN * x_p)
    if not f_start > 0 or f_start >= f_stop:
        raise PlanError(f"cannot size a chirp from {probe.path}: start {f_start:.3g} Hz, stop {f_stop:.3g} Hz")
    return Chirp(duration=duration, gain=gain, sweep="log", f_start=round(f_start, 3), f_stop=round(f_stop, 3),
                 sample_rate=sample_rate)


def plan_experiments(device: str | Bench, settings: DeviceSettings | None = None, *,
                     probe_dir: str | Path = "plan-probe", sample_rate: int = 10000, duration: float = 20.0,
                     seed: int = 0, overwrite: bool = False,
                     progress: Callable[[Progress], None] | None = None,
                     on_probe: Callable[[ProbeResult], None] | None = None) -> Plan:
    """Probe the device's break-away and size a campaign from it (the module docstring says how).

    ``device``: a device URL (opened and closed here) or an open :class:`Bench` (its settings are used unless
    ``settings`` is given). ``settings``: the accepted limits and calibration; every planned current stays within
    ``LIMIT_SHARE`` of ``settings.current_limit``. ``probe_dir``: where the probe's run files go
    (``probe-N.h5``; an existing one is refused unless ``overwrite``). ``progress``: the runner's progress
    callback for each probe run; ``on_probe``: called with each probe's result. ``duration`` (s) is the length of
    the identification and the chirp. Raises :class:`PlanError` (no break-away within the limits) or what the
    device raised."""
    own = not isinstance(device, Bench)
    bench = Bench.open(device, settings) if own else device  # type: ignore[arg-type]
    previous = bench.settings  # a caller's bench gets its own settings back
    try:
        if settings is not None:
            bench.settings = settings
        try:
            probe, played = probe_breakaway(bench, probe_dir, sample_rate=sample_rate, overwrite=overwrite,
                                            progress=progress, on_probe=on_probe)
        except ProbeError as exc:
            raise PlanError(str(exc)) from None
        used = bench.settings
        runs, notes = size_protocols(probe, used, sample_rate=sample_rate, duration=duration, seed=seed)
        return Plan(bench.url, used, probe, played, runs, notes)
    finally:
        bench.settings = previous
        if own:
            bench.close()
