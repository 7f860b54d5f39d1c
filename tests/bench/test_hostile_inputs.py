"""Hostile input (issue 30): random model JSON to ``hilbench compensate``, random argument lists to
``hilbench sim`` (parsing and checks only, no device, no simulator process), and the single-spot refusals that
belong to no other command's test file (a run file onto a device, ``residual --inertia 0``).

The fuzz tests run with ``HILBENCH_TRACEBACK`` set, so the CLI re-raises instead of printing one line: every
exception that reaches the test must then be one of the project's own error types."""

from __future__ import annotations

import copy
import functools
import json
import os
import stat
import traceback

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hilbench.analysis.errors import AnalysisError
from hilbench.bench import cli
from hilbench.bench.cli import main
from hilbench.bench.errors import BenchError
from hilbench.drivers.errors import DriverError
from hilbench.firmware_sim.devices.sim_config import SimConfigError
from hilbench.firmware_sim.engine.plant import PlantParameterError
from tests.bench.test_identify_command import _write_run

OURS = (BenchError, AnalysisError, DriverError, PlantParameterError, SimConfigError)
# 150 examples each: about 12 s (compensate) and 4 s (sim); HILBENCH_FUZZ_EXAMPLES=1500 for a longer search
FUZZ = settings(max_examples=int(os.environ.get("HILBENCH_FUZZ_EXAMPLES", "150")), deadline=None,
                suppress_health_check=list(HealthCheck), database=None)


@pytest.fixture
def fast_cli(monkeypatch):
    """The CLI with its parser built once (building it takes 0.4 s; parsing reuses it unchanged) and
    HILBENCH_TRACEBACK set, so that every exception reaches the test."""
    monkeypatch.setenv("HILBENCH_TRACEBACK", "1")
    monkeypatch.setattr(cli, "build_parser", functools.cache(cli.build_parser))


class _DeviceReached(Exception):
    """Raised in place of opening a device: every check before it passed."""


def _ours(exc: BaseException, module_suffix: str | None = None) -> bool:
    """One of the project's error types, or a ValueError raised by the command module itself (its own
    one-line message), or argparse's exit 2."""
    if isinstance(exc, SystemExit):
        return exc.code == 2
    if isinstance(exc, OURS):
        return True
    if type(exc) is ValueError and module_suffix:
        return traceback.extract_tb(exc.__traceback__)[-1].filename.endswith(module_suffix)
    return False


# ---- compensate: random model files ----

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=6), inner, max_size=5),
    max_leaves=12)


def _valid_model() -> dict:
    from hilbench.firmware_sim.engine.friction_models import dc_motor

    p = dc_motor(4)
    k = np.asarray(p.ms_stiffness)
    return {"schema": "hilbench.friction-model/2", "family": "maxwell_slip", "data": {"train": {"file": ""}},
            "parameters": {"axis": "rotary", "units": {"inertia": "kg*m^2"}, "inertia": p.inertia,
                           "ms_stiffness": k.tolist(), "ms_delta": (np.asarray(p.ms_slip) / k).tolist(),
                           "viscous": p.viscous, "coulomb": 0.0, "offset": 0.0, "spring": 0.0, "std_errors": {}}}


def _valid_comparison() -> dict:
    from hilbench.firmware_sim.engine.friction_models import dc_motor

    plant = dc_motor(4).replace(torque_constant=1.0).to_dict()
    return {"schema": "hilbench.compare/1", "axis": "rotary",
            "rows": [{"model": "maxwell_slip", "fit": {"units": {}}, "plant": plant},
                     {"model": "lugre", "fit": {"units": {}}, "plant": dict(plant)}]}


PATHS = [("schema",), ("family",), ("data",), ("data", "train"), ("data", "train", "file"), ("parameters",),
         ("parameters", "axis"), ("parameters", "inertia"), ("parameters", "ms_stiffness"),
         ("parameters", "ms_delta"), ("parameters", "viscous"), ("parameters", "coulomb"), ("parameters", "offset"),
         ("parameters", "spring"), ("parameters", "std_errors"), ("parameters", "units"), ("plant",)]
ROW_PATHS = [("axis",), ("rows",), ("rows", 1), ("rows", 1, "model"), ("rows", 1, "fit"), ("rows", 1, "plant"),
             ("rows", 0, "plant", "inertia"), ("rows", 0, "plant", "ms_stiffness"), ("rows", 0, "plant", "ms_slip"),
             ("rows", 1, "plant", "lugre"), ("rows", 1, "plant", "gms"), ("rows", 1, "plant", "cogging"),
             ("rows", 1, "plant", "current_limit"), ("rows", 1, "plant", "restoring_table"),
             ("rows", 0, "plant", "seed")]


def _set(doc, path, value):
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


@st.composite
def model_documents(draw):
    kind = draw(st.sampled_from(["random", "model", "comparison", "family"]))
    if kind == "random":
        return draw(JSON)
    if kind == "comparison":
        doc, paths = _valid_comparison(), ROW_PATHS
    else:
        doc, paths = _valid_model(), PATHS
        if kind == "family":
            doc["family"] = draw(st.sampled_from(["lugre", "gms", "dahl", "unicorn", "maxwell_slip"]))
            doc["plant"] = _valid_comparison()["rows"][1]["plant"]
    for path in draw(st.lists(st.sampled_from(paths), min_size=1, max_size=3)):
        try:
            _set(doc, path, draw(JSON))
        except (KeyError, IndexError, TypeError):  # an earlier mutation removed the parent: keep what is there
            pass
    return doc


@pytest.fixture
def model_path(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz") / "model.json"


def test_random_model_files_end_in_our_errors_only(model_path, monkeypatch, fast_cli):

    def reached(*args, **kwargs):
        raise _DeviceReached

    monkeypatch.setattr("hilbench.bench.acquisition.runner.Bench.open", reached)
    reached_device = []

    @FUZZ
    @given(doc=model_documents(), feedforward=st.sampled_from(["maxwell_slip", "coulomb", "lugre", "none"]))
    def check(doc, feedforward):
        model_path.write_text(json.dumps(copy.deepcopy(doc), allow_nan=True))
        try:
            main(["compensate", str(model_path), "--feedforward", feedforward, "--reference", "point_to_point",
                  "--targets", "0.001", "--move-time", "0.01", "--rest", "0", "--sample-rate", "1000", "-q"])
        except _DeviceReached:
            reached_device.append(doc)  # a valid model: every check passed, the device would open now
        except BaseException as exc:  # noqa: BLE001 (the point of the test: which exceptions escape)
            if not _ours(exc):
                raise AssertionError(f"{type(exc).__name__} escaped compensate for {json.dumps(doc)[:300]}") \
                    from exc

    check()
    assert reached_device  # the strategy also produced valid models, so the checks are not refusing everything


# ---- sim: random argument lists (parsing and checks; the simulator is never started) ----

SIM_TOKENS = ["--serial", "--can", "--canopen", "--odrive", "--moteus", "--clock", "--udp-port", "--interface",
              "--node",
              "--fd", "--config", "--seed", "--pacing", "--tick"]
SIM_VALUES = ["vcan0", "0", "1", "15", "16", "-1", "99999999999999999999", "nan", "inf", "-inf", "1e400", "0.004",
              "real", "sync", "realtime", "lockstep", "socketcan", "virtual", "udp_multicast", "nope", "",
              "239.74.163.2", "{missing}", "{config}", "{bad_config}", "{folder}"]


def test_random_sim_arguments_end_in_our_errors_only(tmp_path, monkeypatch, fast_cli):
    started = []

    def execv(path, argv):
        started.append(argv)
        raise _DeviceReached

    monkeypatch.setattr(os, "execv", execv)
    config = tmp_path / "sim.toml"
    config.write_text("[plant]\nelements = 4\n")
    bad = tmp_path / "bad.toml"
    bad.write_text("[plant]\nelements = 'many'\n")
    values = [v.format(missing=tmp_path / "none.toml", config=config, bad_config=bad, folder=tmp_path)
              for v in SIM_VALUES]

    @FUZZ
    @given(argv=st.lists(st.sampled_from(SIM_TOKENS) | st.sampled_from(values), max_size=8))
    def check(argv):
        try:
            main(["sim", *argv])
        except _DeviceReached:
            pass
        except BaseException as exc:  # noqa: BLE001
            if not _ours(exc, "bench/cli/commands/sim.py"):
                raise AssertionError(f"{type(exc).__name__} escaped `hilbench sim {' '.join(argv)}`") from exc

    check()


# ---- single refusals ----

def test_a_run_file_is_never_renamed_over_a_device_or_a_fifo(tmp_path, capsys):
    # item 17 for run files: an HDF5 run seeks, so it cannot be streamed into a device; it is refused, not renamed
    src = tmp_path / "x.csv"
    src.write_text("t,position,torque\n0,0,1\n0.001,0.1,1\n0.002,0.2,1\n")
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    assert main(["import", "csv", str(src), "-o", str(fifo), "--overwrite"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "is not a regular file" in err
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    dev = tmp_path / "null"
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        return
    assert main(["import", "csv", str(src), "-o", str(dev), "--overwrite"]) == 2
    assert stat.S_ISCHR(os.stat(dev).st_mode) and sorted(p.name for p in tmp_path.iterdir()) == [
        "null", "pipe", "x.csv"]


def test_residual_inertia_zero_on_a_torque_driven_record_is_one_line(tmp_path, capsys):
    # item 12: "zero-size array to reduction operation maximum which has no identity" (numpy's words)
    run = tmp_path / "run.h5"
    _write_run(run, 1)
    assert main(["residual", str(run), "--inertia", "0", "--json", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--inertia 0 is for a displacement-driven record" in err and "zero-size" not in err
