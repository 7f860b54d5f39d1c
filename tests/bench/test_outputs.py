"""bench.storage.outputs and the commands that write through it (issue 12 item 3 and the disk-full part of item 4;
issue 13: ``--json -``). An output never overwrites an input; an existing file is replaced only by a complete
new one."""

import contextlib
import errno
import hashlib
import json
import os
import socket
import stat
import subprocess
import threading

import pytest

from hilbench.analysis.output_files import OutputError
from hilbench.bench.cli import main
from hilbench.bench.errors import BenchError
from hilbench.bench.storage import outputs
from tests.bench.test_identify_command import _write_run


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("outputs") / "run.h5"
    _write_run(path, 1)
    return path


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("argv", [
    ["show", "{run}", "--json", "{run}"],
    ["identify", "{run}", "--json", "{run}"],
    ["identify", "{run}", "--json", "{tmp}/m.json", "--validate", "{link}"],
    ["residual", "{run}", "--json", "{link}"],
    ["afrf", "{run}", "--json", "{run}"],
    ["afrf", "{run}", "--plot", "{link}"],
    ["skeleton", "{run}", "--mass", "1", "--json", "{run}"],
])
def test_an_output_naming_an_input_is_refused_in_one_line(argv, run_file, tmp_path, capsys):
    link = tmp_path / "alias.h5"
    os.symlink(run_file, link)  # the same file under another name
    before = _digest(run_file)
    args = [a.format(run=run_file, tmp=tmp_path, link=link) for a in argv]
    if "--validate" in argv:  # the validation run is an input too: name it as the output
        args[args.index("--json") + 1] = str(link)
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "is an input of this command" in err
    assert _digest(run_file) == before


def test_json_dash_writes_to_stdout_and_keeps_stdout_pure(run_file, capsys):
    assert main(["show", str(run_file), "--json", "-"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["n_samples"] == 20000  # stdout is the JSON alone
    assert captured.err.startswith(str(run_file))  # the human summary moved to stderr
    assert not os.path.exists("-")
    assert main(["identify", str(run_file), "--json", "-"]) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)  # nothing but the model on stdout
    assert doc["schema"].startswith("hilbench.friction-model")
    assert "verdict:" in captured.err and not os.path.exists("-")


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "out.json"
    target.write_text('{"old": true}\n')

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(outputs.os, "fsync", full)
    with pytest.raises(OSError, match="No space left"):
        outputs.write_json(target, {"new": list(range(1000))})
    assert json.loads(target.read_text()) == {"old": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_a_value_json_cannot_encode_fails_before_the_old_file_is_touched(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old\n")
    with pytest.raises(TypeError):
        outputs.write_json(target, {"x": object()})
    assert target.read_text() == "old\n" and len(list(tmp_path.iterdir())) == 1


def _strict_loads(text: str):
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def test_json_is_strict_nan_and_infinities_are_null_even_when_a_caller_allows_nan(tmp_path):
    # issue 30 item 16: presliding.json held bare NaN ("force_rules": NaN), which standard parsers reject
    np = pytest.importorskip("numpy")
    target = tmp_path / "out.json"
    outputs.write_json(target, {"a": float("nan"), "b": [float("inf"), -np.inf, np.float64("nan")],
                                "c": np.array([1.5, np.nan]), "d": (np.int64(3), np.bool_(True))}, allow_nan=True)
    assert _strict_loads(target.read_text()) == {"a": None, "b": [None, None, None], "c": [1.5, None],
                                                 "d": [3, True]}


def _char_device(folder):
    dev = folder / "null"
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # the /dev/null device, in a temporary folder
    except PermissionError:
        pytest.skip("mknod of a character device needs root (CAP_MKNOD)")
    return dev


@pytest.mark.parametrize("command", ["show", "identify"])
def test_a_character_device_output_is_written_into_never_replaced(command, run_file, tmp_path):
    # issue 30 item 17: `show RUN --json /dev/null` as root replaced /dev/null with a regular file
    dev = _char_device(tmp_path)
    assert main([command, str(run_file), "--json", str(dev), "-q"]) == 0
    mode = os.stat(dev).st_mode
    assert stat.S_ISCHR(mode) and os.stat(dev).st_rdev == os.makedev(1, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null"]  # no temporary left beside it


def test_a_fifo_output_is_written_into_and_stays_a_fifo(run_file, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    try:
        assert main(["show", str(run_file), "--json", str(fifo), "-q"]) == 0
    finally:
        if reader.is_alive():  # unblock the reader if the command never opened the FIFO
            with contextlib.suppress(OSError):
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        reader.join(10)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert _strict_loads(got[0].decode())["n_samples"] == 20000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_a_socket_output_is_refused_in_one_line(run_file, tmp_path, capsys):
    path = tmp_path / "s"
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(path))
    try:
        assert main(["show", str(run_file), "--json", str(path)]) == 2
    finally:
        sock.close()
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "is a socket" in err
    assert stat.S_ISSOCK(os.stat(path).st_mode)


def test_replacement_keeps_the_mode_and_is_complete(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old\n")
    os.chmod(target, 0o640)
    outputs.write_json(target, {"a": 1})
    assert json.loads(target.read_text()) == {"a": 1} and (target.stat().st_mode & 0o777) == 0o640


def test_refuse_inputs_rejects_a_folder_target(tmp_path):
    with pytest.raises(OutputError, match="is a folder"):
        outputs.write_text(tmp_path, "x")


@pytest.fixture
def tiny_fs(tmp_path):
    """A 64 KiB tmpfs (root with CAP_SYS_ADMIN only)."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    cp = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True)
    if cp.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root with CAP_SYS_ADMIN); the injected ENOSPC test covers it")
    yield mnt
    subprocess.run(["umount", str(mnt)], check=False)


def test_disk_full_on_a_real_small_filesystem_keeps_the_old_file(tiny_fs):
    target = tiny_fs / "summary.json"
    target.write_text('{"old": 1}\n')
    with pytest.raises(OSError) as exc:
        outputs.write_json(target, {"big": "x" * 200_000})
    assert exc.value.errno == errno.ENOSPC
    assert json.loads(target.read_text()) == {"old": 1}
    assert [p.name for p in tiny_fs.iterdir()] == ["summary.json"]


def test_a_late_output_that_is_a_declared_input_is_refused_at_write_time(tmp_path):
    # compare names models/FAMILY.json only after fitting: the check is where every output is written
    precious = tmp_path / "models" / "lugre.json"
    precious.parent.mkdir()
    precious.write_text("input\n")
    outputs.begin_command()
    try:
        outputs.refuse_inputs({"--output": tmp_path / "compare.json"}, [precious])
        with pytest.raises((BenchError, OutputError), match="is an input of this command"):
            outputs.write_json(tmp_path / "models" / ".." / "models" / "lugre.json", {"x": 1})
    finally:
        outputs.begin_command()
    assert precious.read_text() == "input\n" and sorted(p.name for p in precious.parent.iterdir()) == ["lugre.json"]
