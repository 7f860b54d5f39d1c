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

A load on a spring (the probe's restoring fit, a least squares with a spring term over every moving sample, shows
one; :mod:`hilbench.analysis.breakaway.probe` says when a spring is recognised) is probed once more, slowly and at
the cap (:func:`_probe_spring`), and sized against the spring's force as well as the friction
(:func:`_spring_protocols`: the mass-spring response to a sine force with Coulomb friction, Den Hartog; its chirp
crosses resonance with a swing bounded by the probe's travel, :func:`swing_bound`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from hilbench.bench.acquisition.breakaway_probe import (
    SPRING_SHARE,
    BreakawayProbe,
    ProbeError,
    ProbeResult,
    analyse_probe,
)
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
#: A load on a spring is probed once more, at the cap, with slow cosine ramps and returns of this many natural
#: periods, so that it follows the current quasi-statically instead of swinging at sqrt(k/J): a linear ramp's
#: corner would start a swing of (change of the ramp rate)/(k*omega_n), and a swing faster than the ramp's speed
#: runs the load backwards (inner presliding loops; docs/cli.md gives the paper system's figures).
SPRING_RAMP_PERIODS = 15.0
#: Stepped-sine frequencies of a load on a spring, as fractions of its natural frequency (below resonance).
SPRING_STEP_RATIOS = (0.2, 0.5)
#: A spring load's chirp crosses resonance with CHIRP_MARGIN x its crossing amplitude within the swing bound: the
#: passage overshoots the amplitude it leaves (the Cornu spiral's first loop, about 1.2 x) and the off-resonance
#: response adds to it.
CHIRP_MARGIN = 1.5


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

    def _spring_text(self) -> str:
        """The spring of the probe, in words: a spring load's from the fit of its slides; a free load's from the
        restoring fit (the least squares with a spring term over every moving sample, which tells the two apart),
        as the noise it is there (nothing without that fit)."""
        p = self.probe
        fit = (p.sliding if p.spring else p.restoring) or {}
        if "spring_per_kt" not in fit:
            return ""
        k = fit["spring_per_kt"] * self.settings.torque_constant
        if p.spring:
            rest = fit.get("rest_position", math.nan)
            return (f", spring k = {k:.4g} N*m/rad resting at {rest:.4g} rad (natural frequency "
                    f"{natural_frequency(p):.4g} Hz; the friction is what the current leaves after k*x, J*a and b*v)")
        return (f", spring k = {k:.3g} N*m/rad (no restoring force: |k| x travel is {100 * self.spring_share:.2g} % "
                f"of the sliding current; a spring's is at least {100 * SPRING_SHARE:g} % of the probe's peak)")

    @property
    def spring_share(self) -> float:
        """The restoring fit's spring force over the probe's travel, |k/Kt| * travel, as a share of the sliding
        current: about 0 on a load without a spring (at least probe.SPRING_SHARE of the peak on a spring load,
        which is then probed slowly and sized against its spring)."""
        fit = self.probe.restoring or {}
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
               (f"  friction at the slides' ends (current less k*x and J*a): +{p.positive:.4g} A, {p.negative:.4g} A"
                if p.spring else f"  break-away (speed above {p.velocity_threshold:.3g} rad/s): +{p.positive:.4g} A, "
                                 f"{p.negative:.4g} A"),
               f"  sliding current (fit of the slides): +{fit['positive']:.4g} A, {fit['negative']:.4g} A "
               f"({fit['positive'] * kt:.4g} N*m, {fit['negative'] * kt:.4g} N*m at {kt:g} N*m/A)",
               f"  inertia J = {fit['inertia_per_kt'] * kt:.4g} kg*m^2, viscous b = "
               f"{fit['viscous_per_kt'] * kt:.4g} N*m*s/rad" + self._spring_text(),
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
        return (({"m_per_rad"} if proto.unit != "m" else set()) | ({"inertia"} if proto.inertia == 0 else set())
                | ({"presliding_distance"} if proto.unit != "d" else set()))
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
    if isinstance(proto, Presliding) and proto.unit != "d":
        return (f"presliding reversals at {', '.join(f'{a:.4g}' for a in proto.amplitudes)} {proto.unit}, "
                f"{proto.rate:.4g} {proto.unit}/s")
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
    """Play probes of growing peak current until the motor slid both ways with slides long enough to fit (a load
    on a spring: one slow probe at the cap, :func:`_probe_spring`); returns the last probe's result and the run
    files played (``probe_dir/probe-N.h5``)."""
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
            return _probe_spring(bench, found, probe_dir, played, sample_rate=sample_rate, overwrite=overwrite,
                                 progress=progress, on_probe=on_probe)
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


def _probe_spring(bench: Bench, found: ProbeResult, probe_dir: str | Path, played: list[str], *, sample_rate: int,
                  overwrite: bool, progress: Callable[[Progress], None] | None,
                  on_probe: Callable[[ProbeResult], None] | None) -> tuple[ProbeResult, list[str]]:
    """A load on a spring (``found`` from a quick-return probe): one slow probe at the cap. Its returns are as slow
    as its ramps, each :data:`SPRING_RAMP_PERIODS` natural periods long, so the load follows the current instead
    of swinging; the spring bounds its travel (about peak*Kt/k), so the probe goes to the cap at once: the
    farther the slides, the more of them lies where the friction has saturated (analysis.breakaway.probe)."""
    cap = LIMIT_SHARE * bench.settings.current_limit
    fit = found.restoring or {}
    inertia, k = fit.get("inertia_per_kt", math.nan), fit.get("spring_per_kt", math.nan)
    period = 2 * math.pi * math.sqrt(inertia / k) if inertia > 0 and k > 0 else 1.0  # s
    ramp = min(60.0, max(1.5, SPRING_RAMP_PERIODS * period))
    slow = BreakawayProbe(peak=cap, ramp_time=ramp, return_time=ramp, hold=min(10.0, max(0.3, 2 * period)),
                          shape="cosine", sample_rate=sample_rate)
    path = Path(probe_dir) / f"probe-{len(played) + 1}.h5"
    result = bench.run(slow, path, overwrite=overwrite, progress=progress, operator="hilbench plan")
    played.append(str(result.path))
    if result.status != "completed":
        raise PlanError(f"the probe {result.path} ended {result.status}: {result.message}")
    again = analyse_probe(str(result.path))
    if on_probe is not None:
        on_probe(again)
    if again.spring and again.sliding is not None and again.presliding_distance is not None:
        return again, played
    kt = bench.settings.torque_constant
    measured = again if again.spring else found
    fit = measured.restoring or {}
    raise PlanError(f"{measured.path}: a load on a spring (k = {fit.get('spring_per_kt', math.nan) * kt:.4g} "
                    f"N*m/rad, J = {fit.get('inertia_per_kt', math.nan) * kt:.4g} kg*m^2) did not slide far "
                    f"enough for its friction to saturate up to {cap:.3g} A ({LIMIT_SHARE:g} of --current-limit "
                    f"{bench.settings.current_limit:g} A; travel {measured.travel:.3g} rad): raise "
                    f"--current-limit if the motor and the spring allow it")


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

    if probe.spring:
        return _spring_protocols(probe, settings, level, clipped, notes, sample_rate, duration, seed)
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
                    notes: list[str], **shape: float) -> Identification:
    """Quiet half-periods at QUIET_SHARE of the sliding current; loud ones grown on the played input until
    SLIDE_SHARE of the samples drive past 1.1 x the sliding current each way (bisection, 40 halvings). ``shape``:
    the noise's cutoff and the envelope's period (Hz, s) when not the protocol's defaults."""
    from hilbench.bench.acquisition.excitations import lowpass_uniform_noise, rectangular_envelope

    quiet = QUIET_SHARE * level
    base = Identification(duration=duration, amplitude=1.0, offset=0.0, seed=seed, sample_rate=sample_rate, **shape)
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


def natural_frequency(probe: ProbeResult) -> float:
    """sqrt(k/J)/(2 pi) of the probe's fit, Hz (NaN without a positive spring and inertia)."""
    fit = probe.sliding or {}
    k, inertia = fit.get("spring_per_kt", math.nan), fit.get("inertia_per_kt", math.nan)
    return math.sqrt(k / inertia) / (2 * math.pi) if k > 0 and inertia > 0 else math.nan


def _spring_protocols(probe: ProbeResult, settings: DeviceSettings, level: float,
                      clipped: Callable[[float, str], float], notes: list[str], sample_rate: int, duration: float,
                      seed: int) -> tuple[dict[str, Protocol], list[str]]:
    """The campaign of a load on a spring k (a mass J on a spring, with friction): every amplitude overcomes the
    friction plus the spring's force over the displacement it is planned for, at most LIMIT_SHARE of the limit.

    A sine force F0 at omega on a mass-spring with Coulomb friction Fc moves it, in continuous sliding and away from
    resonance, by X = S / |k - J omega^2| with S = sqrt(F0^2 - (4 Fc / pi)^2) (Den Hartog 1931, "Forced vibrations
    with combined Coulomb and viscous friction", Trans. ASME APM-53-9; S. S. Rao, Mechanical Vibrations, section
    "Response of a system with Coulomb damping": the equivalent-viscous solution; 4 Fc / pi is that
    approximation's, Den Hartog's exact condition for continuous sliding of a free mass is F0 > (pi/2) Fc); with
    k = 0 it is the free-mass formula of _chirp. As omega -> 0 it tends to S/k. At resonance the Coulomb friction
    does not bound it once F0 > 4 Fc/pi: the amplitude grows by S/(2 J omega_n) rad per second without limit, and
    a sweep through resonance bounds it only by its speed. So:

    - identification: the noise low-passed at the natural frequency f_n = sqrt(k/J)/(2 pi) (the load follows it
      quasi-statically; above f_n the mass takes the force and the load hardly moves), envelope periods of
      eight natural periods (at least 4 s); loud half-periods sized as for a free load against
      ``I_s + k*x_p/Kt``, the current that holds the load x_p out against the spring and the friction, quiet ones at
      half of it (presliding);
    - stepped sine at r = 0.2 and 0.5 f_n (below resonance), amplitudes STEP_FACTORS x ``I_s + (k/Kt) (1 - r^2)
      x_p`` with r = 0.5, the largest ratio (the softer dynamic stiffness, 0.75 k): 0.5 and 0.8 stay within x_p at
      both frequencies, 2 slides beyond it at both, 1.25 beyond it at 0.5 f_n;
    - chirp: a log sweep from f_n/2 to where X = x_p above resonance, J omega^2 = k + S/x_p, through the
      resonance. A sweep crossing it at d(omega)/dt = omega_n ln(f_stop/f_start)/T (a log sweep of T s) leaves the
      undamped linear oscillator the amplitude X_c = S/(2 J omega_n) sqrt(2 pi T / (omega_n ln(f_stop/f_start)))
      (the passage through resonance; the friction only lowers it): S is the largest with CHIRP_MARGIN X_c within
      the swing the probe showed the load takes (its half travel) and within the device's position window about
      the spring's rest. The plan's notes state X_c and that bound;
    - presliding: as for a free load (nested reversals at 4, 3, 2 and 1 x_p, 2 x_p/s, J), written in rad."""
    fit = probe.sliding or {}
    kt = settings.torque_constant
    k, inertia = fit["spring_per_kt"], fit["inertia_per_kt"]  # A/rad, A*s^2/rad
    x_p = probe.presliding_distance or math.nan
    f_n = natural_frequency(probe)
    holding = level + k * x_p  # A: holds the load x_p out against the spring and the friction
    runs: dict[str, Protocol] = {}
    cap = LIMIT_SHARE * settings.current_limit
    runs["identification"] = _identification(holding, cap, sample_rate, duration, seed, notes,
                                             cutoff=round(max(0.5, f_n), 3), period=round(max(4.0, 8 / f_n), 3))
    frequencies = tuple(round(r * f_n, 4) for r in SPRING_STEP_RATIOS)
    unit = level + k * (1 - max(SPRING_STEP_RATIOS) ** 2) * x_p
    steps = tuple(sorted({round(clipped(f * unit, f"stepped-sine amplitude {f:g} x (I_s + 0.75 k*x_p)"), 6)
                          for f in STEP_FACTORS}))
    runs["stepped_sine"] = SteppedSine(frequencies=frequencies, amplitudes=steps, settle_periods=3,
                                       measure_periods=5, sample_rate=sample_rate)
    runs["chirp"] = _spring_chirp(probe, settings, level, k, inertia, x_p, f_n, clipped, notes, sample_rate,
                                  duration)
    # in rad at the load: a spring load's x_p may exceed what `presliding_distance` (unit d) takes (1 rad)
    runs["presliding"] = Presliding(amplitudes=tuple(round(m * x_p, 6) for m in PRESLIDING_MULTIPLES), unit="rad",
                                    rate=round(2 * x_p, 6), sample_rate=sample_rate,
                                    inertia=round(inertia * kt, 9) if 0 < inertia * kt <= 100 else 0.0)
    return runs, notes


def swing_bound(probe: ProbeResult, settings: DeviceSettings) -> float:
    """rad: the largest swing about the spring's rest a spring load's chirp is sized for: the probe's half travel
    (what the load was seen to take) and the device's position window about the rest, whichever is less."""
    rest = (probe.sliding or {}).get("rest_position", 0.0)
    return min(probe.half_travel or math.nan, rest - settings.position_min, settings.position_max - rest)


def crossing_amplitude(s_force: float, inertia: float, f_n: float, f_start: float, f_stop: float,
                       duration: float) -> float:
    """rad: X_c = S/(2 J omega_n) sqrt(2 pi T / (omega_n ln(f_stop/f_start))), the amplitude a log sweep of
    ``duration`` T s from ``f_start`` to ``f_stop`` (Hz) leaves an undamped oscillator J (A*s^2/rad) of natural
    frequency ``f_n`` (Hz) under the net force S (A) when it crosses its resonance."""
    w_n = 2 * math.pi * f_n
    return s_force / (2 * inertia * w_n) * math.sqrt(2 * math.pi * duration / (w_n * math.log(f_stop / f_start)))


def _spring_chirp(probe: ProbeResult, settings: DeviceSettings, level: float, k: float, inertia: float, x_p: float,
                  f_n: float, clipped: Callable[[float, str], float], notes: list[str], sample_rate: int,
                  duration: float) -> Chirp:
    """The chirp of :func:`_spring_protocols`: the largest net force S (A) whose crossing amplitude, times
    CHIRP_MARGIN, stays within :func:`swing_bound` (bisection: X_c grows with S)."""
    bound = swing_bound(probe, settings)
    f_start = f_n / 2
    coulomb = 4 * level / math.pi  # A: what the friction takes of the force amplitude (equivalent viscous)

    def f_stop_of(s_force: float) -> float:  # Hz: X = x_p above resonance
        return min(math.sqrt((k + s_force / x_p) / inertia) / (2 * math.pi), sample_rate / 20)

    def crossing(s_force: float) -> float:
        return crossing_amplitude(s_force, inertia, f_n, f_start, f_stop_of(s_force), duration)

    if not (bound > 0 and f_stop_of(0.0) > f_start):
        raise PlanError(f"{probe.path}: no chirp: the swing bound is {bound:.3g} rad (the probe's half travel and "
                        f"the position window about the spring's rest)")
    lo, hi = 0.0, math.sqrt(max(0.0, (LIMIT_SHARE * settings.current_limit) ** 2 - coulomb ** 2))
    if CHIRP_MARGIN * crossing(hi) > bound:
        for _ in range(60):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if CHIRP_MARGIN * crossing(mid) <= bound else (lo, mid)
    s_force = lo
    gain = clipped(math.hypot(s_force, coulomb), "chirp gain")
    f_stop = f_stop_of(s_force)
    x_c = crossing(s_force)
    notes.append(f"chirp: crosses the natural frequency {f_n:.4g} Hz with a swing of about {x_c:.3g} rad "
                 f"(X_c at net force {s_force:.3g} A); swing bound {bound:.4g} rad about the spring's rest (the "
                 f"probe's half travel and the position window)")
    return Chirp(duration=duration, gain=round(gain, 6), sweep="log", f_start=round(f_start, 4),
                 f_stop=round(f_stop, 4), sample_rate=sample_rate)


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
