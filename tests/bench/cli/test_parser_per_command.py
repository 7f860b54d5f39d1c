"""Issue 41: a command line builds only its own command's parser. The parser built for one command must answer
exactly as the full one (same help, aliases and nested commands), and each command must map back to the module
that registers it; ``hilbench analyse --help`` and ``hilbench docs`` import none of the other commands' heavy
modules (numpy models, h5py, the acquisition runner)."""

from __future__ import annotations

import argparse
import importlib
import json
import subprocess
import sys

import pytest

from hilbench.bench.cli.main import build_parser, command_module, command_modules, named_command


def _commands(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def _helps(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> dict[tuple[str, ...], str]:
    """Every help text under ``parser``, nested commands and their aliases included, by command path."""
    helps = {path: parser.format_help()}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                helps |= _helps(sub, (*path, name))
    return helps


def _registered_by(module: str) -> set[str]:
    """The command names (aliases included) that ``module``'s register() adds to an empty parser."""
    sub = argparse.ArgumentParser(prog="hilbench").add_subparsers(dest="command")
    importlib.import_module(f"hilbench.bench.cli.commands.{module}").register(sub)
    return set(sub.choices)


@pytest.fixture(scope="module")
def full_helps() -> dict[tuple[str, ...], str]:
    return _helps(build_parser())


def test_every_registered_command_maps_back_to_its_module():
    names = {module: _registered_by(module) for module in command_modules()}
    assert all(names.values()), {m: n for m, n in names.items() if not n}
    for module, registered in names.items():
        for name in registered:  # a module that registers another name (or an alias) is built for nothing
            assert command_module(name) == module, f"{module}.py registers {name!r}: name the module after it"
    assert command_module("import") == "import_"
    assert command_module("no-such-command") is None


@pytest.mark.parametrize("module", command_modules())
def test_one_command_parser_answers_as_the_full_one(module, full_helps):
    (command,) = _registered_by(module)
    parser = build_parser(command)
    assert set(_commands(parser).choices) == {command}
    helps = _helps(parser)
    del helps[()]  # the top level lists the one command; `hilbench -h` builds the full parser
    mine = {path: text for path, text in full_helps.items() if path[:1] == (command,)}
    assert helps.keys() == mine.keys()  # nested commands and their aliases (`run identify`, `import csv`) too
    for path, text in helps.items():
        assert text == mine[path], path


@pytest.mark.parametrize("argv, command", [
    (["analyse", "C", "--help"], "analyse"), (["docs"], "docs"), (["run", "identify"], "run"),
    (["-h"], None), (["--help", "docs"], None), (["--version"], None), (["--vers", "docs"], None), ([], None),
])
def test_the_command_is_the_first_argument_unless_an_option(argv, command):
    assert named_command(argv) == command


def test_unknown_commands_and_other_spellings_get_the_full_parser():
    everything = set(_commands(build_parser()).choices)
    assert set(_commands(build_parser("no-such-command")).choices) == everything
    assert set(_commands(build_parser("import_")).choices) == everything  # "invalid choice" lists them all


HEAVY = ("hilbench.analysis.models.families", "h5py", "hilbench.bench.acquisition.runner")


@pytest.mark.parametrize("argv", [["analyse", "--help"], ["docs"], ["-q", "info", "--help"]])
def test_a_command_imports_only_its_own_module(argv):
    program = (
        "import json, sys\n"
        "from hilbench.bench.cli.main import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))\n")
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
