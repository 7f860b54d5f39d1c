"""Campaigns: a TOML list of runs (protocol, parameters, repeats) played one after another.

    [defaults]                      # applies to every run (protocol parameters and device settings)
    device = "sim://"
    operator = "ab"
    sample_rate = 10000
    current_limit = "8 A"           # a value may carry its unit; it must be the parameter's unit

    [[run]]
    name = "id"
    protocol = "identification"     # identification | chirp | stepped_sine
    repeats = 2
    amplitude = "4 A"
    duration = "10 s"

Output: one run file per run and repeat in the output folder (``<name>-<repeat>.h5``) plus
``index.json``, rewritten atomically after every run. ``--resume`` keeps the runs whose file says
``completed`` and whose stored plan (protocol parameters, device settings, the model file's SHA-256) is the
campaign file's, and redoes the others (a crashed or aborted file is kept beside as ``*.failed-N.h5``, a run
of another plan as ``*.replanned-N.h5``). Every repeat plays its own seed (:func:`repeat_seed`).
Everything is validated before anything moves: a bad key, unit or value is reported with file, line
and reason.
"""

from __future__ import annotations

import json
import os
import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path

from hilbench.bench.acquisition.campaign_plan import (
    GENERAL_KEYS,
    SETTING_UNITS,
    CampaignError,
    PlannedRun,
    line_of,
    plan_changes,
    plant_table,
    repeat_seed,
    resolve_device_url,
    run_plan,
    value,
)
from hilbench.bench.acquisition.protocols import PROTOCOLS, Protocol, ProtocolError
from hilbench.bench.acquisition.runner import Bench, DeviceSettings, Progress, RunControl, SettingsError
from hilbench.bench.campaign_index import INDEX_NAME
from hilbench.bench.errors import BenchError
from hilbench.bench.storage.folder_lock import folder_lock
from hilbench.common.runfile import writer_alive
from hilbench.drivers.device_url import check_device_url
from hilbench.drivers.errors import DeviceURLError

#: Largest campaign file read, bytes: a campaign of a thousand runs is ~100 KB.
MAX_CAMPAIGN_BYTES = 4 << 20
LOCK_NAME = ".campaign.lock"
RUN_KEYS = {"name", "protocol", "repeats"}
@dataclass
class Campaign:
    path: Path
    runs: list[PlannedRun] = field(default_factory=list)

    @property
    def device(self) -> str:
        return self.runs[0].device if self.runs else "sim://"


def load_campaign(path: str | Path) -> Campaign:
    """Parse and validate a campaign file. Raises :class:`CampaignError` (file:line: reason)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:  # bounded: a campaign is a page of TOML, not a FIFO that never ends
            raw = fh.read(MAX_CAMPAIGN_BYTES + 1)
    except OSError as exc:
        raise CampaignError(f"{path}: cannot read: {exc.strerror}") from None
    if len(raw) > MAX_CAMPAIGN_BYTES:
        raise CampaignError(f"{path}: longer than {MAX_CAMPAIGN_BYTES} bytes; is it a campaign?")
    try:
        text = raw.decode("utf-8")
        data = tomllib.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise CampaignError(f"{path}: not valid TOML: {' '.join(str(exc).split())}") from None
    except RecursionError:
        raise CampaignError(f"{path}: not valid TOML: nested too deep") from None
    unknown_top = sorted(set(data) - {"defaults", "run", "compensate", "plant"})
    if unknown_top:
        raise CampaignError(f"{path}:{line_of(text, unknown_top[0], None)}: unknown table or key "
                            f"{unknown_top[0]!r} (expected [defaults], [[run]], [[compensate]] and [plant])")
    try:
        plant = plant_table(data.get("plant", {}), str(path))
    except ValueError as exc:
        raise CampaignError(str(exc)) from None
    steps = data.get("compensate", [])
    if not isinstance(steps, list) or not all(isinstance(t, dict) for t in steps):
        raise CampaignError(f"{path}:{line_of(text, 'compensate', None)}: compensate must be an array of tables "
                            f"([[compensate]])")
    defaults = data.get("defaults", {})
    runs = data.get("run", [])
    if not isinstance(defaults, dict):
        raise CampaignError(f"{path}:{line_of(text, 'defaults', None)}: defaults must be a table "
                            f"([defaults]), got {defaults!r}")
    if not isinstance(runs, list) or not (runs or steps):
        raise CampaignError(f"{path}: no [[run]] tables")
    if not all(isinstance(t, dict) for t in runs):
        raise CampaignError(f"{path}:{line_of(text, 'run', None)}: run must be an array of tables "
                            f"([[run]]), got {runs!r}")
    campaign = Campaign(path)
    names: set[str] = set()
    for i, table in enumerate(runs):
        merged = {**defaults, **table}
        where_table = {k: i for k in table}

        def fail(key: str, reason: str, i: int = i, where_table: dict = where_table) -> CampaignError:
            line = line_of(text, key, where_table.get(key))
            return CampaignError(f"{path}:{line}: run {i + 1}: {reason}")

        proto_name = merged.get("protocol")
        if proto_name not in PROTOCOLS:
            raise fail("protocol", f"protocol must be one of {', '.join(PROTOCOLS)}, got {proto_name!r}")
        cls = PROTOCOLS[proto_name]
        specs = cls.specs()
        name = str(merged.get("name", f"{proto_name}{i + 1}"))
        if not re.match(r"^[A-Za-z0-9_.-]+$", name) or name in names:
            raise fail("name", f"name {name!r} must be unique and use only letters, digits, '_', '.', '-'")
        names.add(name)
        repeats = merged.get("repeats", 1)
        if not isinstance(repeats, int) or isinstance(repeats, bool) or not 1 <= repeats <= 1000:
            raise fail("repeats", f"repeats must be a whole number in [1, 1000], got {repeats!r}")
        mode = merged.get("mode", "current")
        params, setting_values = {}, {}
        for key, raw in merged.items():
            if key in RUN_KEYS or key in GENERAL_KEYS:
                continue
            try:
                if key in specs:
                    # (presliding's amplitudes and rate take the unit its `unit` names: plain numbers)
                    known_unit = mode in ("current", "velocity", "position") and specs[key].unit != "unit"
                    unit = specs[key].unit_for(mode) if known_unit else None
                    params[key] = value(raw, unit or None, key)
                elif key in SETTING_UNITS:
                    setting_values[key] = value(raw, SETTING_UNITS[key], key)
                else:
                    known = sorted(set(specs) | set(SETTING_UNITS) | RUN_KEYS | GENERAL_KEYS)
                    raise ValueError(f"unknown key {key!r} for protocol {proto_name} "
                                     f"(known: {', '.join(known)})")
            except ValueError as exc:
                raise fail(key, str(exc)) from None
        try:
            protocol = cls.from_dict(params)
        except ProtocolError as exc:
            bad = next((k for k in params if str(exc).startswith(k)), "protocol")
            raise fail(bad, str(exc)) from None
        try:
            settings = DeviceSettings(**{**cls.RECOMMENDED_SETTINGS, **setting_values})
        except SettingsError as exc:
            raise fail(str(exc).split()[0], str(exc)) from None
        try:
            protocol.check_memory()
            protocol.excitation(settings.limit_for(protocol))
        except (TypeError, ValueError, ProtocolError) as exc:
            raise fail("protocol", str(exc)) from None
        device = merged.get("device", "sim://")
        if not isinstance(device, str) or "://" not in device:
            raise fail("device", f"device must be a URL like sim:// or serial:///dev/ttyUSB0, got {device!r}")
        try:
            check_device_url(device)
            device = resolve_device_url(device, path.parent)
        except (DeviceURLError, ValueError) as exc:
            raise fail("device", str(exc)) from None
        environment = merged.get("environment", {})
        if not isinstance(environment, dict) or not all(
                isinstance(v, str | int | float) and not isinstance(v, bool) for v in environment.values()):
            raise fail("environment", f"environment must be a table of values, e.g. {{ambient = \"23 C\", "
                                      f"load = \"2 kg\"}}, got {environment!r}")
        for r in range(1, repeats + 1):
            played = protocol
            if r > 1 and "seed" in specs:  # each repeat its own input (all repeats played seed 0 before)
                played = cls.from_dict({**params, "seed": repeat_seed(protocol.seed, r)})  # type: ignore[attr-defined]
            campaign.runs.append(PlannedRun(name, r, played, settings, device,
                                            str(merged.get("operator", "")), str(merged.get("notes", "")),
                                            environment=dict(environment), plant=dict(plant)))
    if steps:  # the compensation matrix: one planned run per case (docs/compensation.md)
        from hilbench.bench.acquisition.compensation_matrix import campaign_step

        for j, table in enumerate(steps):
            campaign.runs += campaign_step(table, defaults, j, path, text)
        if len({r.key for r in campaign.runs}) != len(campaign.runs):
            raise CampaignError(f"{path}: two runs or [[compensate]] steps share a name")
    devices = {r.device for r in campaign.runs}
    if len(devices) > 1:
        raise CampaignError(f"{path}: one campaign runs on one device; found {', '.join(sorted(devices))}")
    return campaign


def read_index_document(out_dir: Path) -> dict:
    """The whole index document ({} when there is none)."""
    path = out_dir / INDEX_NAME
    if not path.exists():
        return {}
    try:
        doc = json.loads(path.read_text())
        if not isinstance(doc, dict) or not isinstance(doc["runs"], list):
            raise TypeError("its runs are not a list")
    except (ValueError, KeyError, TypeError) as exc:
        raise CampaignError(f"{path}: unreadable campaign index ({exc})") from None
    return doc


def read_index(out_dir: Path) -> dict[str, dict]:
    return {e["key"]: e for e in read_index_document(out_dir).get("runs", [])}


def write_index_document(out_dir: Path, doc: dict) -> None:
    """Replace the index atomically and durably (written beside, fsynced, renamed, the folder fsynced)."""
    from hilbench.bench.storage.outputs import dumps

    tmp = out_dir / (INDEX_NAME + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(dumps(doc, indent=2))  # strict JSON
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, out_dir / INDEX_NAME)
    fd = os.open(out_dir, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_index(out_dir: Path, campaign: Campaign, entries: dict[str, dict], uid: str) -> None:
    """The planned runs in plan order, then the runs of an earlier plan that this one no longer has, marked
    ``"planned": false`` (kept: their files are still there; ``hilbench analyse`` skips them)."""
    planned = [r.key for r in campaign.runs]
    runs = [{k: v for k, v in entries[k].items() if k != "planned"} for k in planned if k in entries]
    kept = set(planned)
    runs += [{**e, "planned": False} for k, e in entries.items() if k not in kept]
    doc = {"campaign": str(campaign.path), "schema": "hilbench-campaign-index", "version": 1, "uid": uid,
           "runs": runs}
    write_index_document(out_dir, doc)


def new_campaign_uid() -> str:
    """A campaign's identity (in its index from its first run; results rows are keyed by it, not by the folder's
    name, so that a copied or renamed campaign keeps its rows and two campaigns of one name never share them)."""
    import uuid

    return uuid.uuid4().hex


def _file_status(path: Path) -> str:
    from hilbench.common.runfile import open_run

    try:
        with open_run(path) as run:
            return run.status
    except (BenchError, OSError):
        return "unreadable"


@dataclass
class CampaignProgress:
    index: int        # position of the run in the campaign (0-based)
    total: int
    key: str
    state: str        # "skipped" | "running" | "completed" | "aborted" | ...
    run: Progress | None = None


def run_campaign(campaign: Campaign, out_dir: str | Path, *, resume: bool = False,
                 progress: Callable[[CampaignProgress], None] | None = None,
                 control: RunControl | None = None, bench: Bench | None = None,
                 say: Callable[[str], None] | None = None) -> dict[str, dict]:
    """Play every planned run; returns the index entries by run key. Stops at the first run that does not
    complete (the index says so), unless it was skipped on resume. ``say``: one line when the folder's lock of a
    dead campaign process is taken over."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    def busy(pid):
        return (f"{out_dir}: another campaign is playing into this folder (pid {pid}); wait for it or "
                f"stop it first")
    with folder_lock(out_dir, LOCK_NAME, CampaignError, busy, say):  # one campaign per folder
        entries = _play(campaign, out_dir, resume, progress, control, bench)
        from hilbench.bench.acquisition.compensation_matrix import campaign_report

        campaign_report(campaign, out_dir, entries)  # nothing unless the campaign has [[compensate]] steps
        return entries


def _play(campaign: Campaign, out_dir: Path, resume: bool, progress, control, bench) -> dict[str, dict]:
    doc = read_index_document(out_dir)
    entries = {e["key"]: e for e in doc.get("runs", [])}
    if entries and not resume:
        raise CampaignError(f"{out_dir}: holds a campaign already; use --resume or another folder")
    uid = doc.get("uid") if isinstance(doc.get("uid"), str) else new_campaign_uid()
    planned = {r.key for r in campaign.runs}
    marks = {k for k, e in entries.items() if (e.get("planned") is False) != (k not in planned)}
    if marks or (entries and uid != doc.get("uid")):  # marked before anything plays (a resume may play none)
        _write_index(out_dir, campaign, entries, uid)
    control = control or RunControl()
    own = bench is None
    bench = bench or Bench.open(campaign.device)
    hashes: dict[str, str] = {}
    try:
        for i, planned in enumerate(campaign.runs):
            path = out_dir / f"{planned.key}.h5"
            plan = run_plan(planned, hashes)
            if path.exists():
                if writer_alive(path):
                    raise CampaignError(f"{path}: a live process is still writing this run; not touching it")
                status = _file_status(path)
                aside = "failed"
                if status == "completed" and planned.key in entries:
                    changed = plan_changes(entries[planned.key], plan)
                    if not changed:
                        if progress:
                            progress(CampaignProgress(i, len(campaign.runs), planned.key, "skipped"))
                        continue
                    aside = "replanned"  # a completed run of another plan: kept beside, never mixed in
                    del entries[planned.key]
                    if progress:
                        progress(CampaignProgress(i, len(campaign.runs), planned.key,
                                                  f"plan changed ({'; '.join(changed)}): redone"))
                n = 1
                while (failed := out_dir / f"{planned.key}.{aside}-{n}.h5").exists():
                    n += 1
                os.replace(path, failed)
            bench.settings = planned.settings
            if progress:
                progress(CampaignProgress(i, len(campaign.runs), planned.key, "running"))
            result = bench.run(planned.protocol, path, operator=planned.operator, notes=planned.notes,
                               control=control, plant=planned.plant,
                               progress=(lambda p, i=i, k=planned.key: progress(
                                   CampaignProgress(i, len(campaign.runs), k, "running", p))) if progress else None)
            entries[planned.key] = {
                "key": planned.key, "name": planned.name, "repeat": planned.repeat,
                "protocol": planned.protocol.name, "file": path.name, "status": result.status, "uid": result.uid,
                "samples": result.samples, "parameters": plan["parameters"], "settings": plan["settings"],
                "model_sha256": plan["model_sha256"], "environment": planned.environment,
            }
            _write_index(out_dir, campaign, entries, uid)
            if progress:
                progress(CampaignProgress(i, len(campaign.runs), planned.key, result.status))
            if result.status != "completed":
                break
    finally:
        if own:
            bench.close()
    return entries


def protocol_fields(cls: type[Protocol]) -> list[str]:
    return [f.name for f in fields(cls)]
