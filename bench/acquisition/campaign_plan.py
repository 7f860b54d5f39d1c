"""What a campaign plans, shared by the campaign runner (``campaign.py``) and its ``[[compensate]]`` steps
(``compensation_matrix.py``): the planned run, the campaign file's value syntax, the repeat seeds, and the plan a
run's data depend on, which ``--resume`` compares with the index (docs/campaign.md)."""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hilbench.bench.acquisition.device_options import DEVICE_OPTIONS
from hilbench.bench.acquisition.protocols import Protocol
from hilbench.bench.acquisition.runner import DeviceSettings, settings_dict
from hilbench.bench.errors import BenchError

GENERAL_KEYS = {"device", "operator", "notes", "environment"}
#: the unit of every device setting a campaign may give (the one table of device options)
SETTING_UNITS = {name: unit for name, (unit, _what) in DEVICE_OPTIONS.items()}
QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z*/^0-9]+)?\s*$")


class CampaignError(BenchError):
    """A campaign file that cannot run; the message names the file, the line and the reason."""


def repeat_seed(seed: int, repeat: int) -> int:
    """The seed repeat ``repeat`` (1-based) of a run with ``seed`` plays: repeat 1 the seed itself (a campaign
    of single runs plays as it always did), repeat r > 1 the first 32-bit word of numpy's
    ``SeedSequence([seed, r])``, so repeats play different inputs and runs of different seeds do not share
    them."""
    if repeat == 1:
        return seed
    import numpy as np

    return int(np.random.SeedSequence([seed, repeat]).generate_state(1, np.uint32)[0])


@dataclass
class PlannedRun:
    name: str
    repeat: int
    protocol: Protocol
    settings: DeviceSettings
    device: str
    operator: str = ""
    notes: str = ""
    report: dict[str, float] = field(default_factory=dict)  # a [[compensate]] step's metric settings (SI)
    environment: dict[str, Any] = field(default_factory=dict)  # operator's values, e.g. {"ambient": "23 C"}
    plant: dict[str, float] = field(default_factory=dict)  # the campaign's [plant] (SI), into the run's calibration

    @property
    def key(self) -> str:
        return f"{self.name}-{self.repeat}"


def line_of(text: str, key: str, section_index: int | None) -> int:
    """Line (1-based) of ``key =`` in the n-th ``[[run]]`` table (or in [defaults] when None)."""
    lines = text.splitlines()
    start, seen = 0, -1
    for i, line in enumerate(lines):
        s = line.strip()
        if section_index is None and s == "[defaults]":
            start = i
            break
        if section_index is not None and s == "[[run]]":
            seen += 1
            if seen == section_index:
                start = i
                break
    for i in range(start, len(lines)):
        if re.match(rf"\s*{re.escape(key)}\s*=", lines[i]):
            return i + 1
    return start + 1


def value(raw: Any, unit: str | None, what: str) -> Any:
    """A TOML value; a string ``"<number> <unit>"`` is checked against ``unit`` and becomes a number."""
    if isinstance(raw, str) and unit is not None:
        m = QUANTITY.match(raw)
        if not m:
            raise ValueError(f"{what}: {raw!r} is not a number with a unit")
        given = m.group(2) or unit
        if given != unit:
            raise ValueError(f"{what}: unit {given!r} is wrong, expected {unit!r}")
        number = float(m.group(1))
        return int(number) if number.is_integer() and unit in ("counts", "periods", "Hz") else number
    if isinstance(raw, list):
        return [value(v, unit, what) for v in raw]
    return raw


def model_sha256(planned: PlannedRun, cache: dict[str, str]) -> str | None:
    """SHA-256 of the model file a compensated run's feed-forward comes from (None: the run has none)."""
    model = getattr(planned.protocol, "model", "")
    if not isinstance(model, str) or not model:
        return None
    if model not in cache:
        digest = hashlib.sha256()
        try:
            with open(model, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    digest.update(block)
        except OSError as exc:
            raise CampaignError(f"{model}: cannot read the model file ({exc.strerror})") from None
        cache[model] = digest.hexdigest()
    return cache[model]


def run_plan(planned: PlannedRun, cache: dict[str, str]) -> dict[str, Any]:
    """What a run's data depend on, as the index stores it: protocol, parameters, device settings, and the
    model file's content (its SHA-256) for a compensated run."""
    from hilbench.bench.storage.outputs import dumps

    plan = {"protocol": planned.protocol.name, "parameters": planned.protocol.parameters(),
            "settings": settings_dict(planned.settings), "model_sha256": model_sha256(planned, cache)}
    return json.loads(dumps(plan))  # as it reads back from index.json (tuples as lists, NaN as null)


#: device URL options that name a file (sim's simulator config, canopen's EDS)
FILE_OPTIONS = ("config", "eds")


def resolve_device_url(url: str, folder: Path) -> str:
    """``url`` with every file it names (:data:`FILE_OPTIONS`) made absolute against ``folder`` (the campaign
    file's), as ``[[compensate]] model`` is; ValueError names the option and the file when it does not exist."""
    from urllib.parse import parse_qsl, urlencode, urlsplit

    split = urlsplit(url)
    query = parse_qsl(split.query, keep_blank_values=True)
    resolved = []
    for key, text in query:
        if key in FILE_OPTIONS and text:
            path = Path(text).expanduser()
            path = path if path.is_absolute() else folder / path
            if not path.is_file():
                raise ValueError(f"device option {key}={text}: no file {path} (a relative path is read from the "
                                 f"campaign file's folder)")
            text = str(path.resolve())
        resolved.append((key, text))
    if resolved == query:
        return url
    head = url[: len(url) - len(split.query)] if url.endswith(split.query) else url.partition("?")[0] + "?"
    return head + urlencode(resolved, safe="/")  # (geturl would drop the empty authority of sim://?...)


def plant_table(raw: Any, where: str) -> dict[str, float]:
    """A campaign's ``[plant]`` table (what is known of the load, e.g. ``inertia = "0.0022 kg*m^2"``, as
    ``hilbench plan`` writes it) in SI numbers; ValueError names the key."""
    from hilbench.bench.acquisition.runner import PLANT_UNITS

    if not isinstance(raw, dict):
        raise ValueError(f"{where}: plant must be a table ([plant]), got {raw!r}")
    out = {}
    for key, raw_value in raw.items():
        if key not in PLANT_UNITS:
            raise ValueError(f"{where}: unknown [plant] key {key!r} (known: {', '.join(PLANT_UNITS)})")
        number = value(raw_value, PLANT_UNITS[key], f"[plant] {key}")
        if isinstance(number, bool) or not isinstance(number, int | float) or not 0 < number < float("inf"):
            raise ValueError(f"{where}: [plant] {key} must be a positive number in {PLANT_UNITS[key]}, "
                             f"got {raw_value!r}")
        out[key] = float(number)
    return out


def plan_changes(entry: dict, plan: dict) -> list[str]:
    """The parts of ``plan`` a stored index ``entry`` differs in (empty: the same plan). With the model's
    SHA-256 on both sides the model's path is not compared (the folder may have moved); an entry of an older
    index without it is compared on parameters and settings."""
    changed = []
    old, new = dict(entry.get("parameters") or {}), dict(plan["parameters"])
    if entry.get("protocol") == "presliding" and "repeats" in old:  # the loop count's old name (issue 38)
        old["cycles"] = old.pop("repeats")
        if isinstance(old.get("units"), dict):
            old["units"] = {("cycles" if k == "repeats" else k): v for k, v in old["units"].items()}
    if entry.get("model_sha256") and plan["model_sha256"]:
        old.pop("model", None)
        new.pop("model", None)
        if entry["model_sha256"] != plan["model_sha256"]:
            changed.append("model file content")
    if entry.get("protocol") != plan["protocol"]:
        changed.append("protocol")
    diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    if diff:
        changed.append("parameters " + ", ".join(diff))
    old_s, new_s = entry.get("settings") or {}, plan["settings"]
    diff = sorted(k for k in set(old_s) | set(new_s) if old_s.get(k) != new_s.get(k))
    if diff:
        changed.append("settings " + ", ".join(diff))
    return changed


