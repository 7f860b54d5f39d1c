"""The firmware core on an emulated Cortex-M4F (QEMU ``mps2-an386``): build the image, start QEMU with
the board's UART on a host pseudo-terminal, and say which Debian package is missing when it cannot.

Used by the ``target`` tests and the firmware benchmark. The firmware sources live in the repository's
``firmware/`` folder (not in an installed wheel). See docs/firmware.md.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # tests/firmware/ -> the repository
FIRMWARE = ROOT / "firmware"
PACINGS = ("lockstep", "realtime")
QEMU_START_TIMEOUT = 20.0  # s, for QEMU to name its pseudo-terminal


def missing_tools() -> str | None:
    """One line naming what the emulated target needs and this machine lacks, or None."""
    if not (FIRMWARE / "Makefile").is_file():
        return "the firmware sources (firmware/) are not part of this installation"
    needs = []
    cc = shutil.which("arm-none-eabi-gcc")
    if cc is None:
        needs.append("gcc-arm-none-eabi")
    else:
        libc = subprocess.run([cc, "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16",
                               "--specs=nano.specs", "-print-file-name=libc_nano.a"],
                              capture_output=True, text=True).stdout.strip()
        if not os.path.isabs(libc):
            needs.append("libnewlib-arm-none-eabi")
    if shutil.which("qemu-system-arm") is None:
        needs.append("qemu-system-arm")
    if shutil.which("make") is None:
        needs.append("make")
    if needs:
        return f"needs {', '.join(needs)} (as root: apt-get install {' '.join(needs)}, or `make toolchain`)"
    return None


def build_image(pacing: str = "lockstep", sim_config: str | None = None, build_dir: Path | None = None) -> Path:
    """Cross-compile the mps2-an386 image for ``pacing`` (or ``"nucleo-f446re"``: the board port); returns
    the ELF path. ``sim_config``: the simulator TOML whose plant the QEMU image embeds (default: the
    packaged one)."""
    if pacing not in (*PACINGS, "nucleo-f446re"):
        raise ValueError(f"pacing must be one of {PACINGS} or nucleo-f446re, got {pacing!r}")
    build = Path(build_dir) if build_dir is not None else FIRMWARE / "build"
    target = build / (f"{pacing}.elf" if pacing == "nucleo-f446re" else f"an386-{pacing}.elf")
    cmd = ["make", "-s", "-C", str(FIRMWARE), f"BUILD={build}", f"PYTHON={sys.executable}", str(target)]
    if sim_config:
        cmd.append(f"SIM_CONFIG={Path(sim_config).resolve()}")
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"firmware build failed: {(res.stderr or res.stdout).strip().splitlines()[-1:]}")
    return target


def size(elf: Path) -> dict[str, int]:
    """``arm-none-eabi-size`` of an image: text, data and bss bytes; flash = text + data, RAM = data + bss."""
    out = subprocess.run(["arm-none-eabi-size", str(elf)], capture_output=True, text=True, check=True).stdout
    text, data, bss = (int(v) for v in out.splitlines()[1].split()[:3])
    return {"text": text, "data": data, "bss": bss, "flash": text + data, "ram": data + bss}


def _die_with_parent() -> None:
    """In the child, before exec: SIGKILL when the parent dies (Linux prctl PR_SET_PDEATHSIG), so a host
    that is itself killed (SIGKILL, a crashed test run) never leaves an emulator spinning."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: stop_qemu and the process group remain
        pass


def start_qemu(elf: Path, icount: int | None = None) -> tuple[subprocess.Popen, str]:
    """Start QEMU on ``elf`` with UART0 on a new pseudo-terminal; returns the process and the pty path.

    QEMU runs in its own process group (stopped as a group by :func:`stop_qemu`) and is killed by the
    kernel if the process that started it dies first (strictly, the starting thread: start QEMU from a
    thread that outlives it). Prefer :func:`running_qemu`, which stops it on every exit path.

    ``icount``: ``-icount shift=N``, every guest instruction advances guest time by 2**N ns, so the
    guest clock follows the instruction count, not the host clock (deterministic, not real time).
    """
    cmd = ["qemu-system-arm", "-M", "mps2-an386", "-display", "none", "-monitor", "none", "-serial", "pty",
           "-kernel", str(elf)]
    if icount is not None:
        cmd += ["-icount", f"shift={icount}"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, process_group=0,
                            preexec_fn=_die_with_parent)
    try:
        deadline = time.monotonic() + QEMU_START_TIMEOUT
        text = b""
        while True:
            match = re.search(rb"(/dev/pts/\d+)", text)
            if match:
                return proc, match.group(1).decode()
            ready, _, _ = select.select([proc.stdout], [], [], max(0.0, deadline - time.monotonic()))
            chunk = os.read(proc.stdout.fileno(), 4096) if ready else b""
            if not chunk:
                raise RuntimeError(f"QEMU did not offer its UART: {text.decode(errors='replace').strip()[-200:]}")
            text += chunk
    except BaseException:
        stop_qemu(proc)
        raise


@contextlib.contextmanager
def running_qemu(elf: Path, icount: int | None = None) -> Iterator[tuple[subprocess.Popen, str]]:
    """``with running_qemu(elf) as (proc, pty):`` QEMU on ``elf``, stopped however the block ends."""
    proc, pty = start_qemu(elf, icount)
    try:
        yield proc, pty
    finally:
        stop_qemu(proc)


def stop_qemu(proc: subprocess.Popen, grace: float = 5.0) -> None:
    """Stop QEMU's whole process group (SIGTERM, then SIGKILL after ``grace`` s) and reap it."""
    import signal

    for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, None)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=wait)
            break
        except subprocess.TimeoutExpired:
            continue
    proc.wait()
    if proc.stdout is not None:
        proc.stdout.close()
