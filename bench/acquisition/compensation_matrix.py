"""The compensation matrix: every feed-forward of a model file against every reference, on a device or
predicted offline, and its report (docs/compensation.md).

A case is one :class:`~hilbench.bench.acquisition.compensation.CompensatedReference` run. On a device it is played by
:meth:`Bench.run` (position mode; the run file keeps the position setpoint and the feed-forward current) and
the metrics are computed from the run file's position and commanded current. ``predict`` runs the same
control law on the model itself (:mod:`hilbench.analysis.compensation.closed_loop`): what the model expects,
not a measurement.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hilbench.analysis.compensation.closed_loop import PositionGains, simulate_tracking
from hilbench.analysis.compensation.feedforward import load_compensators
from hilbench.analysis.compensation.metrics import tracking_metrics
from hilbench.analysis.compensation.report import CaseResult, document, markdown_table, section_table, write_plots
from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.model_file import _clean as json_safe
from hilbench.bench.acquisition.compensation import Case
from hilbench.bench.errors import BenchError
from hilbench.bench.storage import outputs

#: Default references of the matrix (rad, Hz, s): presliding to gross sliding sines, a triangle, moves.
DEFAULT_REFERENCES: dict[str, dict] = {
    "sine": {"amplitudes": (2e-4, 1e-3, 1e-2, 0.1), "frequency": 0.5, "cycles": 2, "rest": 0.5},
    "triangle": {"amplitude": 0.05, "frequency": 0.5, "cycles": 2, "corner": 0.02, "rest": 0.5},
    "point_to_point": {"targets": (0.05, -0.05, 0.0), "move_time": 0.3, "rest": 0.7},
}
OUTPUTS = ("compensation.md", "compensation.json")


@dataclass
class MatrixSettings:
    """What every case shares: metric window (s), settling tolerance (rad), the current limit (A) and the
    calibration (N*m/A, 1) the feed-forward is converted with."""

    window: float = 0.05
    tolerance: float = 1e-4
    current_limit: float = 20.0
    torque_constant: float = 0.2
    ratio: float = 1.0


def named_runs(model_doc: dict) -> list[str]:
    """The run files a model or comparison document names (its training and validation runs): inputs of a
    command that reads the model, so never one of its outputs (compensate -o id.h5 replaced the training run)."""
    data = model_doc.get("data")
    if not isinstance(data, dict):
        return []
    found = [data.get("file")] + [part.get("file") for part in data.values() if isinstance(part, dict)]
    return [f for f in found if isinstance(f, str) and f and "\0" not in f]


def check_calibration(model_doc: dict, torque_constant: float, ratio: float) -> str:
    """Refuse a model identified under another calibration than the device's. The model file names its
    training run; when that run file is readable, its calibration must equal ``torque_constant`` (N*m/A) and
    ``ratio`` to 1e-9. Returns a note on what was checked."""
    from hilbench.common.runfile import open_run

    data = model_doc.get("data") if isinstance(model_doc.get("data"), dict) else {}
    train = data.get("train") if isinstance(data.get("train"), dict) else None
    if train is None and isinstance(data.get("file"), str):
        train = data
    path = train.get("file") if train else None
    if not isinstance(path, str) or not path or "\0" in path or not Path(path).is_file():
        return "calibration not checked: the model's training run file is not here"
    try:
        with open_run(path) as run:
            cal = run.calibration
    except Exception as exc:  # an unreadable training run is not the user's fault here: say so, go on
        return f"calibration not checked: {path}: {exc}"
    for name, device in (("torque_constant", torque_constant), ("ratio", ratio)):
        model = cal.get(name)
        if model is not None and not math.isclose(float(model), device, rel_tol=1e-9):
            unit = " N*m/A" if name == "torque_constant" else ""
            raise BenchError(f"the model was identified with {name} {float(model):g}{unit} ({path}); the device "
                             f"is configured with {device:g}{unit}: identify again or use that calibration")
    return f"calibration matches the model's training run {path}"


def cases(model: str, references: dict[str, dict], names: list[str] | None, settings: MatrixSettings,
          sample_rate: int) -> list[Case]:
    """Every (reference, feed-forward) protocol, reference outer; ``names`` restricts the feed-forwards."""
    comps, _ = load_compensators(model)
    available = [c.name for c in comps]
    chosen = names or available
    unknown = [n for n in chosen if n not in available]
    if unknown:
        raise BenchError(f"{model} offers feed-forward {', '.join(available)}; not {', '.join(unknown)}")
    path = str(Path(model).resolve())
    out = [Case(kind, tuple(params.items()), path, name, sample_rate, settings.torque_constant, settings.ratio)
           for kind, params in references.items() for name in chosen]
    for case in out:  # every reference and feed-forward is built (and checked) before anything moves
        case.feedforward_result(settings.current_limit)
    return out


def case_file(case: Case) -> str:
    """File name of a case's run in the matrix folder; the feed-forward's name is a plain identifier (checked
    when the model file is read), so the name never leaves the folder."""
    name = f"{case.reference}-{case.compensation}.h5"
    if "/" in name or "\0" in name or name.startswith("."):
        raise BenchError(f"feed-forward {case.compensation!r}: not a plain name")
    return name


def predict_case(case: Case, plant, gains: PositionGains, settings: MatrixSettings,
                 counts_per_rev: int = 0) -> CaseResult:
    """Simulate one case on ``plant`` (load-side PlantParams whose torque constant is k_t*ratio, N*m/A). The
    device's loop acts on the motor-shaft error ratio*e, so at the load its gains are ratio*(kp, ki, kd);
    the encoder resolution at the load is 2*pi/(counts_per_rev*ratio) (0 counts: exact)."""
    ref = case.reference_path
    ff = case.feedforward_result(settings.current_limit)
    r = settings.ratio
    load_gains = PositionGains(gains.kp * r, gains.ki * r, gains.kd * r, gains.i_limit, gains.d_cutoff)
    lsb = 2 * math.pi / (counts_per_rev * r) if counts_per_rev > 0 else 0.0
    run = simulate_tracking(plant, ref.position, ff.current, ref.fs, load_gains, settings.current_limit, lsb)
    m = tracking_metrics(ref, run.position, run.current, window=settings.window, tolerance=settings.tolerance)
    return CaseResult(ref, case.compensation, m, ref.position - run.position, ff.clipped)


def measured_case(case: Case, run_file: str | Path, settings: MatrixSettings) -> CaseResult:
    """Metrics of a played case from its run file (position rad, commanded current A), by the registry's
    ``compensation`` analysis (hilbench.analysis.protocol), which rebuilds the reference from the run file."""
    from hilbench.analysis.compensation.entry import TrackingSettings, reference_head
    from hilbench.analysis.protocol import ReadOptions, entry

    analysis = entry("compensation")
    inputs = analysis.read([run_file], ReadOptions(allow_incomplete=True))
    m = analysis.analyse(inputs, TrackingSettings(settings.window, settings.tolerance)).value
    # the samples the analysis scored: a host-clocked drive's grid may end one short of the reference
    ref = reference_head(case.reference_path, inputs.record.position.size)
    ff = case.feedforward_result(settings.current_limit)
    return CaseResult(ref, case.compensation, m, ref.position - inputs.record.position, ff.clipped, str(run_file))


def write_report(results: list[CaseResult], out: Path, settings: dict) -> list[Path]:
    """compensation.md (the table), compensation.json and compensation_<reference>.png in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    table = markdown_table(results)
    by_section = section_table(results)
    table += "\n" + by_section if by_section else ""
    header = ("Feed-forward compensation matrix (docs/compensation.md). Error = reference - measured position; "
              f"glitch = peak |error| within {settings['window_s'] * 1e3:g} ms after each reversal of the "
              f"reference; settling to {settings['tolerance_rad'] * 1e3:g} mrad; effort = rms commanded current."
              f" Source: {settings['source']}.\n\n")
    outputs.write_text(out / "compensation.md", header + table)
    outputs.write_json(out / "compensation.json", json_safe(document(results, settings)), indent=1, allow_nan=False)
    plots = write_plots(results, out, save=lambda fig, path: outputs.save_figure(fig, path, dpi=110))
    return [out / "compensation.md", out / "compensation.json", *plots]


def single_outputs(run_file: Path, baseline: bool) -> dict[str, Path]:
    """What one run (``hilbench compensate`` without --matrix) writes beside its run file ``<stem>.h5``: the
    baseline run ``<stem>-baseline.h5`` (when ``baseline``), the figure ``<stem>-tracking.png`` and the summary
    ``<stem>-tracking.json``. Keys: run, baseline, figure, summary."""
    stem = run_file.stem if run_file.suffix == ".h5" else run_file.name
    out = {"run": run_file, "baseline": run_file.with_name(stem + "-baseline.h5"),
           "figure": run_file.with_name(stem + "-tracking.png"), "summary": run_file.with_name(stem + "-tracking.json")}
    if not baseline:
        del out["baseline"]
    return out


def write_single_report(run: CaseResult, baseline: CaseResult | None, paths: dict[str, Path], settings: dict,
                        title: str) -> list[Path]:
    """The summary (the matrix's JSON document of the run and its baseline) and the figure of one run."""
    import matplotlib.pyplot as plt

    from hilbench.analysis.compensation.run_report import run_figure

    results = [run] if baseline is None else [run, baseline]
    paths["summary"].parent.mkdir(parents=True, exist_ok=True)  # --predict -o new/p.h5: no run file made it
    outputs.write_json(paths["summary"], json_safe(document(results, settings)), indent=1, allow_nan=False)
    fig = run_figure(run, baseline, title)
    try:
        outputs.save_figure(fig, paths["figure"], dpi=110)
    finally:
        plt.close(fig)
    return [paths["summary"], paths["figure"]]


def run_cases(protocols: list[Case], play: Callable[[Case, int], CaseResult],
              say: Callable[[str], None] = print) -> list[CaseResult]:
    """Play every case in turn (``play(protocol, index)``), printing one line per case."""
    results = []
    for i, p in enumerate(protocols):
        r = play(p, i)
        m = r.metrics
        say(f"[{i + 1}/{len(protocols)}] {p.reference} / {p.compensation}: rms error {m.rms_error * 1e3:.4g} mrad, "
            f"glitch mean {m.glitch_mean * 1e3:.4g} mrad, effort {m.effort_rms:.4g} A, clipped {r.clipped}")
        results.append(r)
    return results



# ---- campaigns: a [[compensate]] step is the matrix, one planned run per case ----

STEP_KEYS = {"name", "model", "references", "feedforwards", "sample_rate"}


def campaign_step(table: dict, defaults: dict, index: int, path: Path, text: str) -> list:
    """The planned runs of the ``index``-th ``[[compensate]]`` table of campaign ``path`` (docs/campaign.md):
    every feed-forward of ``model`` against every reference, named ``<name>.<reference>.<feed-forward>``.
    Raises :class:`CampaignError` naming file, line and reason."""
    from hilbench.bench.acquisition.campaign_plan import (
        GENERAL_KEYS,
        SETTING_UNITS,
        CampaignError,
        PlannedRun,
        line_of,
        value,
    )
    from hilbench.bench.acquisition.runner import DeviceSettings, SettingsError

    merged = {**{k: v for k, v in defaults.items() if k in SETTING_UNITS or k in GENERAL_KEYS}, **table}

    def fail(key: str, reason: str) -> CampaignError:
        line = line_of(text, key, None) if key not in table else _step_line(text, key, index)
        return CampaignError(f"{path}:{line}: compensate {index + 1}: {reason}")

    name = merged.get("name", f"compensate{index + 1}")
    if not isinstance(name, str) or not re.match(r"^[A-Za-z0-9_][A-Za-z0-9_-]*$", name):
        # the name is the report's folder OUT/<name>/ and the first part of every run's file name
        raise fail("name", f"name {name!r} must use only letters, digits, '_' and '-' (not first), no '.' or '/'")
    if "model" not in merged or not isinstance(merged["model"], str):
        raise fail("model", "needs model = \"MODEL.json\" (hilbench identify or hilbench compare)")
    model = Path(merged["model"])
    model = model if model.is_absolute() else path.parent / model
    references, settings_values = {}, {}
    kinds = merged.get("references", list(DEFAULT_REFERENCES))
    if not isinstance(kinds, list) or not kinds or any(k not in DEFAULT_REFERENCES for k in kinds):
        raise fail("references", f"references must be a list of {', '.join(DEFAULT_REFERENCES)}, got {kinds!r}")
    units = {"amplitudes": "rad", "amplitude": "rad", "frequency": "Hz", "cycles": "periods", "corner": "s",
             "targets": "rad", "move_time": "s", "rest": "s"}
    metric_units = {"window": "s", "tolerance": "rad"}  # the report's glitch window and settling band
    values, metrics = {}, {}
    for key, raw in merged.items():
        try:
            if key in units:
                values[key] = value(raw, units[key], key)
            elif key in metric_units:
                metrics[key] = value(raw, metric_units[key], key)
                if not (isinstance(metrics[key], float | int) and math.isfinite(metrics[key]) and metrics[key] > 0):
                    raise ValueError(f"{key} must be > 0 {metric_units[key]}, got {raw!r}")
            elif key in SETTING_UNITS:
                settings_values[key] = value(raw, SETTING_UNITS[key], key)
            elif key not in STEP_KEYS and key not in GENERAL_KEYS:
                raise ValueError(f"unknown key {key!r} (known: "
                                 f"{', '.join(sorted(STEP_KEYS | set(units) | set(metric_units)))} and "
                                 f"the device settings)")
        except ValueError as exc:
            raise fail(key, str(exc)) from None
    for kind in kinds:
        params = dict(DEFAULT_REFERENCES[kind])
        params.update({k: tuple(v) if isinstance(v, list) else v for k, v in values.items() if k in params})
        references[kind] = params
    try:
        settings = DeviceSettings(**settings_values)
    except SettingsError as exc:
        raise fail(str(exc).split()[0], str(exc)) from None
    matrix = MatrixSettings(current_limit=settings.current_limit, torque_constant=settings.torque_constant,
                            ratio=settings.ratio, **metrics)
    names = merged.get("feedforwards")
    try:
        from hilbench.bench.acquisition.compensation import CompensatedReference

        _, doc = load_compensators(model)
        check_calibration(doc, settings.torque_constant, settings.ratio)
        found = cases(str(model), references, names, matrix, int(merged.get("sample_rate", 10000)))
        protocols = [CompensatedReference.of(c, matrix.window, matrix.tolerance) for c in found]
    except (BenchError, AnalysisError) as exc:
        raise fail("model", str(exc)) from None
    try:  # a relative simulator config or EDS is read from the campaign file's folder, as the model is
        from hilbench.bench.acquisition.campaign_plan import resolve_device_url

        device = resolve_device_url(str(merged.get("device", "sim://")), path.parent)
    except ValueError as exc:
        raise fail("device", str(exc)) from None
    return [PlannedRun(f"{name}.{p.reference}.{p.compensation}", 1, p, settings, device,
                       str(merged.get("operator", "")), str(merged.get("notes", "")),
                       {"window": matrix.window, "tolerance": matrix.tolerance}) for p in protocols]


def _step_line(text: str, key: str, index: int) -> int:
    """Line (1-based) of ``key =`` in the index-th ``[[compensate]]`` table."""
    count, inside = -1, False
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("["):
            count += stripped == "[[compensate]]"
            inside = stripped == "[[compensate]]" and count == index
        elif inside and stripped.split("=")[0].strip() == key:
            return n
    return 1


def campaign_report(campaign, out_dir: Path, entries: dict[str, dict]) -> list[Path]:
    """After a campaign: the matrix report of every ``[[compensate]]`` step whose runs all completed, in
    ``out_dir/<name>/`` (nothing when the campaign has none)."""
    from hilbench.bench.acquisition.compensation import CompensatedReference

    steps: dict[str, list] = {}
    for planned in campaign.runs:
        if isinstance(planned.protocol, CompensatedReference):
            steps.setdefault(planned.name.split(".")[0], []).append(planned)
    from hilbench.bench.acquisition.campaign_plan import plan_changes, run_plan

    written, hashes = [], {}
    for step, runs in steps.items():
        if not all(entries.get(r.key, {}).get("status") == "completed" for r in runs):
            continue
        if any(plan_changes(entries[r.key], run_plan(r, hashes)) for r in runs):
            continue  # a report combines runs of one plan only (resume redoes the others first)
        settings = runs[0].settings
        matrix = MatrixSettings(current_limit=settings.current_limit, torque_constant=settings.torque_constant,
                                ratio=settings.ratio, **runs[0].report)
        results = [measured_case(r.protocol.case, out_dir / entries[r.key]["file"], matrix) for r in runs]
        meta = {"source": f"campaign {campaign.path}, device {runs[0].device}", "model": runs[0].protocol.model,
                "window_s": matrix.window, "tolerance_rad": matrix.tolerance,
                "current_limit_a": settings.current_limit, "torque_constant_nm_per_a": settings.torque_constant,
                "ratio": settings.ratio, "sample_rate_hz": runs[0].protocol.sample_rate}
        written += write_report(results, out_dir / step, meta)
    return written
