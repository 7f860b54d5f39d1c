"""Issue 13 item 4: one name for one thing across the CLI; global flags anywhere; a closed pipe ends quietly;
a default device from HILBENCH_DEVICE or the config file."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hilbench.bench.acquisition.protocols import PROTOCOLS
from hilbench.bench.acquisition.user_config import config_path, default_device
from hilbench.bench.cli import build_parser, main, split_global_flags
from hilbench.common.runfile import open_run
from tests.bench.test_identify_command import _write_run


@pytest.fixture(scope="module")
def parser():
    return build_parser()


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("vocabulary") / "run.h5"
    _write_run(path, 3)
    return path


def test_run_uses_the_campaign_protocol_names(parser):
    for name, cls in PROTOCOLS.items():  # the names campaigns, run files and the GUI use
        args = parser.parse_args(["run", name])
        assert args.protocol_class is cls
    # the old spellings remain as aliases of the same protocol
    assert parser.parse_args(["run", "identify"]).protocol_class is PROTOCOLS["identification"]
    assert parser.parse_args(["run", "afrf"]).protocol_class is PROTOCOLS["stepped_sine"]


@pytest.mark.parametrize("argv, dest", [
    (["run", "identification", "-o", "X"], "out"),
    (["run", "chirp", "--output", "X"], "out"),
    (["campaign", "c.toml", "--output", "X"], "out"),
    (["paper", "--output", "X"], "out"),
    (["demo", "--output", "X"], "out"),
    (["import", "csv", "f.csv", "--output", "X"], "output"),
    (["import", "emps", "f.mat", "-o", "X"], "output"),
])
def test_output_is_dash_o_or_dash_dash_output_everywhere(parser, argv, dest):
    assert str(getattr(parser.parse_args(argv), dest)) == "X"


def test_replacing_an_existing_file_is_overwrite_everywhere(parser):
    assert parser.parse_args(["run", "chirp", "--overwrite"]).overwrite
    assert parser.parse_args(["import", "csv", "f.csv", "--overwrite"]).force
    assert parser.parse_args(["import", "csv", "f.csv", "--force"]).force  # the old name still works
    assert "--force" not in parser._subparsers._group_actions[0].choices["import"].format_help()


def test_frequencies_are_one_list_syntax(parser):
    run = parser.parse_args(["run", "stepped_sine", "--frequencies", "2", "5", "10"])
    afrf = parser.parse_args(["afrf", "--model", "coulomb", "--frequencies", "2", "5", "10"])
    assert list(run.frequencies) == list(afrf.frequencies) == [2.0, 5.0, 10.0]


def test_afrf_model_frequency_list(tmp_path):
    out = tmp_path / "c.json"
    assert main(["afrf", "--model", "coulomb", "--amplitudes", "10", "--frequencies", "0.5", "1",
                 "--settle-periods", "5", "--settle-time", "0", "--measure-periods", "2",
                 "--samples-per-period", "100", "--workers", "1", "--json", str(out)]) == 0
    import json

    assert json.loads(out.read_text())["frequencies"] == pytest.approx([0.5, 1.0], rel=1e-3)


def test_global_flags_are_taken_from_anywhere():
    rest, flags = split_global_flags(["show", "r.h5", "--traceback", "-q", "--", "-v"])
    assert rest == ["show", "r.h5", "--", "-v"] and flags == {"traceback", "quiet"}


def test_traceback_after_the_subcommand(tmp_path):
    missing = str(tmp_path / "missing.h5")
    assert main(["show", missing]) == 2
    with pytest.raises(Exception, match="missing"):
        main(["show", missing, "--traceback"])


def test_quiet_and_verbose_after_the_subcommand(run_file, tmp_path, capsys):
    assert main(["identify", str(run_file), "--json", str(tmp_path / "m.json"), "-q"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert main(["identify", str(run_file), "--json", str(tmp_path / "m.json"), "--verbose", "--overwrite"]) == 0
    captured = capsys.readouterr()
    assert "verdict:" in captured.out and f"wrote {tmp_path / 'm.json'}" in captured.err


def test_a_closed_pipe_ends_quietly(run_file):
    # `hilbench show RUN | head -0`: the reader is gone before the command writes
    proc = subprocess.Popen([sys.executable, "-m", "hilbench", "show", str(run_file), "--events", "5"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert err == ""


def test_default_device_from_environment_then_config_file(tmp_path, monkeypatch):
    monkeypatch.delenv("HILBENCH_DEVICE", raising=False)
    monkeypatch.delenv("HILBENCH_CONFIG", raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    assert config_path() == tmp_path / "hilbench" / "config.toml"
    assert default_device() == "sim://"
    (tmp_path / "hilbench").mkdir()
    (tmp_path / "hilbench" / "config.toml").write_text('device = "serial:///dev/ttyUSB7?baud=2000000"\n')
    assert default_device() == "serial:///dev/ttyUSB7?baud=2000000"
    monkeypatch.setenv("HILBENCH_DEVICE", "can://virtual/bench9?node=2")
    assert default_device() == "can://virtual/bench9?node=2"
    other = tmp_path / "other.toml"
    other.write_text('device = "not a url"\n')
    monkeypatch.delenv("HILBENCH_DEVICE")
    monkeypatch.setenv("HILBENCH_CONFIG", str(other))
    assert main(["info"]) == 2


def test_info_uses_hilbench_device(monkeypatch, capsys):
    monkeypatch.setenv("HILBENCH_DEVICE", "nonsense")
    assert main(["info"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "HILBENCH_DEVICE" in err and "not a device URL" in err


def test_cli_help_and_readme_name_the_same_commands():
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert "hilbench run identification\\|chirp\\|stepped_sine" in readme
    assert "hilbench skeleton RUN.h5 [RUN2.h5 ...] --mass" in readme
    env = {**os.environ, "HILBENCH_DEVICE": ""}
    cp = subprocess.run([sys.executable, "-m", "hilbench", "--help"], capture_output=True, text=True, env=env)
    assert "anywhere on the line" in cp.stdout and "HILBENCH_DEVICE" in cp.stdout


def test_every_help_text_is_plain_text():
    """Help texts come partly from docstrings: no reST markup (double backquotes, Sphinx roles) reaches the
    terminal, in any subcommand's description, epilog or option help."""
    import argparse

    from hilbench.bench.cli import build_parser

    texts = []

    def walk(parser):
        texts.extend([parser.description or "", parser.epilog or ""])
        for action in parser._actions:
            texts.append(action.help or "")
            if isinstance(action, argparse._SubParsersAction):
                texts.extend(c.help or "" for c in action._choices_actions)
                for sub in action.choices.values():
                    walk(sub)

    walk(build_parser())
    assert len(texts) > 200
    bad = [t for t in texts if "``" in t or ":func:`" in t or ":class:`" in t]
    assert bad == []


# -- issue 28 item 4: one quiet, consistent CLI --------------------------------------------------------------------

#: options through which a command names what it writes
OUTPUT_OPTIONS = {"-o", "--output", "--json", "--plot", "--plots", "--report"}
#: commands that write but never replace: `campaign` resumes a folder (--resume) and refuses another campaign's;
#: `analyse` adds rows to its results table, keyed by run content, settings and version (resume is its default)
NEVER_REPLACES = {"campaign", "analyse"}


def _leaf_commands(parser, path=()):
    import argparse

    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield " ".join(path), parser
        return
    seen = set()
    for name, sub in subs[0].choices.items():
        if id(sub) not in seen:  # aliases share a parser
            seen.add(id(sub))
            yield from _leaf_commands(sub, (*path, name))


def _options(parser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings}


def _writing_commands() -> list:
    return [c for c, p in _leaf_commands(build_parser()) if _options(p) & OUTPUT_OPTIONS and c not in NEVER_REPLACES]


@pytest.mark.device_free
@pytest.mark.parametrize("command", _writing_commands())
def test_every_command_that_writes_replaces_only_with_overwrite(parser, command):
    leaf = dict(_leaf_commands(parser))[command]
    assert "--overwrite" in _options(leaf), f"{command} writes ({sorted(_options(leaf) & OUTPUT_OPTIONS)}) " \
                                            f"but has no --overwrite"


def test_identify_and_show_refuse_an_existing_json_without_overwrite(run_file, tmp_path, capsys):
    """`identify` rejected --overwrite and silently replaced its JSON while `run` refused without it."""
    for argv in (["identify", str(run_file), "--thresholds", "8"], ["show", str(run_file)]):
        out = tmp_path / f"{argv[0]}.json"
        out.write_text("mine\n")
        assert main([*argv, "--json", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "--overwrite" in err and str(out) in err
        assert out.read_text() == "mine\n"  # nothing lost
        assert main([*argv, "--json", str(out), "--overwrite", "-q"]) == 0
        assert json.loads(out.read_text())
        assert main([*argv, "--json", "-", "-q"]) == 0  # standard output is no file to protect
        capsys.readouterr()


@pytest.mark.device_free
def test_the_analysis_commands_refuse_an_existing_output_before_reading_anything(tmp_path, capsys):
    """afrf, skeleton, residual, compare, paper and drift replaced their outputs silently (issue 28): each refuses in
    one line naming --overwrite before it reads an input (the run named here does not even exist); nothing is lost."""
    mine = tmp_path / "mine.json"
    mine.write_text("mine\n")
    (tmp_path / "paper").mkdir()
    (tmp_path / "cmp").mkdir()
    (tmp_path / "cmp" / "compare.json").write_text("mine\n")
    (tmp_path / "paper" / "summary.json").write_text("mine\n")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "results.parquet").write_text("not read\n")
    (tmp_path / "results" / "drift").mkdir()
    (tmp_path / "results" / "drift" / "drift.json").write_text("mine\n")
    missing = str(tmp_path / "no-such-run.h5")
    for argv, kept in ((["afrf", missing, "--json", str(mine)], mine),
                       (["afrf", missing, "--plot", str(mine)], mine),
                       (["skeleton", missing, "--json", str(mine)], mine),
                       (["residual", missing, "--json", str(mine)], mine),
                       (["compare", missing, "--validate", missing, "-o", str(tmp_path / "cmp")],
                        tmp_path / "cmp" / "compare.json"),
                       (["paper", "-o", str(tmp_path / "paper"), "--quick"], tmp_path / "paper" / "summary.json"),
                       (["drift", str(tmp_path / "results")], tmp_path / "results" / "drift" / "drift.json")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "--overwrite" in err and str(kept) in err, (argv, err)
        assert kept.read_text() == "mine\n"


def test_demo_refuses_a_used_folder_without_overwrite(tmp_path, capsys):
    (tmp_path / "model.json").write_text("{}")
    assert main(["demo", "-o", str(tmp_path), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "model.json of a demo already; use --overwrite" in err and (tmp_path / "model.json").read_text() == "{}"


def test_informational_lines_only_with_verbose(tmp_path, capsys):
    """-q: nothing but errors; the default: results and warnings; -v: also what the command only reports back
    (here: the torque timing the user declared, echoed by import)."""
    src = tmp_path / "lab.csv"
    src.write_text("t,position,torque\n" + "".join(f"{k / 1000},{k * 1e-4},{0.1 * (k % 7)}\n" for k in range(2000)))
    argv = ["import", "csv", str(src), "--torque-timing", "hold_previous"]
    assert main([*argv, "-o", str(tmp_path / "a.h5")]) == 0
    normal = capsys.readouterr().out
    assert normal.startswith(f"wrote {tmp_path / 'a.h5'}:") and "torque timing" not in normal
    assert main([*argv, "-o", str(tmp_path / "b.h5"), "-v"]) == 0
    assert "torque timing: hold_previous (stored in the run file)" in capsys.readouterr().out
    assert main([*argv, "-o", str(tmp_path / "c.h5"), "-q"]) == 0
    assert capsys.readouterr().out == ""


def test_campaign_and_run_are_silent_with_quiet(tmp_path, capsys):
    toml = tmp_path / "c.toml"
    toml.write_text('[defaults]\ndevice = "sim://?pacing=lockstep"\n[[run]]\nname = "c"\nprotocol = "chirp"\n'
                    'duration = "0.5 s"\ngain = "1 A"\n')
    assert main(["campaign", str(toml), "-o", str(tmp_path / "camp"), "-q"]) == 0
    assert main(["run", "chirp", "--duration", "0.5", "--device", "sim://?pacing=lockstep", "-o",
                 str(tmp_path / "r.h5"), "-q"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert main(["run", "chirp", "--duration", "0.5", "--device", "sim://?pacing=lockstep", "-o",
                 str(tmp_path / "r2.h5")]) == 0  # the printed path is the file written
    assert capsys.readouterr().out.strip().startswith(f"completed: {tmp_path / 'r2.h5'} (5000 samples")


@pytest.mark.device_free
def test_parameter_errors_name_the_option_not_the_python_name(capsys):
    """Walk every protocol parameter and device setting of `run`: a value out of range is refused in one line
    that starts with the option the user typed (--cutoff), never the dataclass field (cutoff = ...)."""
    from hilbench.bench.acquisition.device_options import DEVICE_OPTIONS

    checked = 0
    for name, cls in PROTOCOLS.items():
        for key, spec in cls.specs().items():
            if spec.kind not in ("float", "int") or spec.maximum is None or key == "sample_rate":
                continue
            flag = "--" + key.replace("_", "-")
            assert main(["run", name, flag, str(spec.maximum * 10 + 10)]) == 2, (name, flag)
            err = capsys.readouterr().err.strip()
            assert err.startswith(f"hilbench run: error: {flag} ") and "\n" not in err, err
            checked += 1
        for key in ("current_limit", "watchdog_timeout", "torque_constant"):
            flag = "--" + key.replace("_", "-")
            assert key in DEVICE_OPTIONS and main(["run", name, flag, "-1"]) == 2
            err = capsys.readouterr().err.strip()
            assert err.startswith(f"hilbench run: error: {flag} ") and "\n" not in err, err
    assert main(["run", "chirp", "--sample-rate", "3000"]) == 2
    assert capsys.readouterr().err.startswith("hilbench run: error: --sample-rate 3000 Hz")
    assert checked > 20


def test_fault_show_and_clear_use_the_default_device(monkeypatch, capsys):
    monkeypatch.setenv("HILBENCH_DEVICE", "sim://?pacing=lockstep")
    assert main(["fault", "show"]) == 0
    assert capsys.readouterr().out.startswith("faults: none")
    assert main(["fault", "clear"]) == 0
    assert "cleared; faults now: none" in capsys.readouterr().out


def test_a_watchdog_trip_says_what_tripped_and_which_option_to_raise(tmp_path, monkeypatch, capsys):
    """Under load the run ended with 'stream ended by the device at sample N: WATCHDOG' and nothing else."""
    from hilbench.drivers import protocol as wire
    from hilbench.drivers.amplifier import Amplifier
    from hilbench.drivers.errors import DeviceFaultError

    def tripped(self, setpoints, *a, **k):  # the device's own words when its watchdog fires
        raise DeviceFaultError("stream ended by the device at sample 99: WATCHDOG", int(wire.Fault.WATCHDOG))
        yield

    monkeypatch.setattr(Amplifier, "stream", tripped)
    out = tmp_path / "w.h5"
    assert main(["run", "chirp", "--duration", "0.5", "--watchdog-timeout", "0.2", "--device",
                 "sim://?pacing=lockstep", "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "WATCHDOG" in err and "watchdog tripped" in err
    assert "0.2 s (--watchdog-timeout)" in err and "raise --watchdog-timeout" in err and "fault clear" in err
    with open_run(out) as run:  # the run file's fault event carries the same words
        assert run.status == "aborted" and "raise --watchdog-timeout" in run.events["message"][-1]
