"""``hilbench gui [--device URL]``: the operator window (live plots, protocols, E-STOP, run browser)."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

# What Qt's xcb platform plugin loads on Linux besides an X11 or Wayland session (Qt 6.5+ docs, "Qt for X11
# Requirements"); Debian/Ubuntu package names.
QT_SYSTEM_LIBRARIES = ("libxcb-cursor0", "libxkbcommon-x11-0", "libxcb-icccm4", "libxcb-keysyms1", "libxcb-shape0",
                       "libegl1", "libgl1", "libfontconfig1", "libdbus-1-3")
HEADLESS_PLATFORMS = ("offscreen", "minimal", "vnc")
PROBE = "from PySide6.QtWidgets import QApplication; QApplication(['hilbench-probe'])"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "gui",
        help="open the operator window (connect, live plots, run protocols, E-STOP, browse runs)",
        description=(
            "The lab operator's window: connect to the amplifier, watch current, torque, position and velocity "
            "live, start identification / chirp / stepped-sine runs, E-STOP (button or Esc), browse and "
            "analyse run files, and play campaigns. Device I/O never runs in the GUI thread. Needs a display "
            f"(X11 or Wayland) and the system libraries {', '.join(QT_SYSTEM_LIBRARIES)}."
        ),
    )
    parser.add_argument("--device", default=None,
                        help="device URL shown in the connection panel (default $HILBENCH_DEVICE, the config "
                             "file's 'device', else sim://, the simulated bench)")
    parser.add_argument("--connect", action="store_true", help="connect to --device at start-up")
    parser.add_argument("--runs", default="runs", metavar="DIR",
                        help="folder for new run files and the run browser (default runs)")
    parser.add_argument("--open", metavar="RUN.h5", help="open this run file in the run browser")
    parser.set_defaults(func=run)


def display_problem(env: dict[str, str] | None = None) -> str | None:
    """Why Qt cannot open a window here, or None. Qt aborts the whole process (SIGABRT) when its platform plugin
    cannot start, so the check runs before Qt is loaded: from the environment first, then by starting a
    QApplication in a child process."""
    env = dict(os.environ if env is None else env)
    platform = env.get("QT_QPA_PLATFORM", "").split(":")[0]
    if platform in HEADLESS_PLATFORMS:
        return None
    if sys.platform.startswith("linux"):
        x11, wayland = env.get("DISPLAY"), env.get("WAYLAND_DISPLAY")
        if platform == "xcb" and not x11:
            return "QT_QPA_PLATFORM=xcb but DISPLAY is not set"
        if platform.startswith("wayland") and not wayland:
            return f"QT_QPA_PLATFORM={platform} but WAYLAND_DISPLAY is not set"
        if not platform and not x11 and not wayland:
            return "neither DISPLAY nor WAYLAND_DISPLAY is set"
    try:
        probe = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        return "Qt did not start within 60 s"
    if probe.returncode == 0:
        return None
    lines = [ln.strip() for ln in probe.stderr.splitlines() if ln.strip() and "Traceback" not in ln]
    hint = next((ln for ln in lines if "could not" in ln.lower() or "cannot" in ln.lower()), lines[-1] if lines
                else f"exit status {probe.returncode}")
    return f"Qt failed to start: {hint[:200]}"


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.errors import BenchError

    if "://" not in args.device:
        raise ValueError(f"--device {args.device!r} is not a device URL (sim://, serial:///dev/ttyUSB0, "
                         f"can://socketcan/can0)")
    try:
        import pyqtgraph  # noqa: F401
        import PySide6  # noqa: F401
    except ImportError as exc:
        raise OSError(f"the GUI needs PySide6 and pyqtgraph: {exc}") from None
    problem = display_problem()
    if problem:
        raise BenchError(
            f"no usable display ({problem}); the GUI needs an X11 or Wayland session and Qt's system libraries "
            f"(Debian/Ubuntu: apt-get install {' '.join(QT_SYSTEM_LIBRARIES)}); "
            "on a machine without a screen use the command-line tools, or QT_QPA_PLATFORM=offscreen for tests"
        )
    from hilbench.bench.gui.app import run_app

    return run_app(device=args.device, runs_dir=args.runs, autoconnect=args.connect, open_file=args.open)
