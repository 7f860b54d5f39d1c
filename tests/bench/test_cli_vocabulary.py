"""Issue 13 item 4: one name for one thing across the CLI; global flags anywhere; a closed pipe ends quietly;
a default device from HILBENCH_DEVICE or the config file."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hilbench.bench.acquisition.protocols import PROTOCOLS
from hilbench.bench.acquisition.user_config import config_path, default_device
from hilbench.bench.cli import build_parser, main, split_global_flags
from tests.bench.test_identify_command import _write_run

pytestmark = pytest.mark.usefixtures("starts_devices")  # starts a device: the serial realtime part of make test


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
    assert main(["identify", str(run_file), "--json", str(tmp_path / "m.json"), "--verbose"]) == 0
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
