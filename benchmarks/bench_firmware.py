"""The firmware core: cost per sample on the host, the emulated Cortex-M4's highest real-time rate, image sizes.

1. ns per sample of the device (decode setpoint frames, limits, plant step, encode sample frames): the C
   core through cffi against a plain Python/numpy loop of the same work (:func:`ns_per_sample_reference`,
   the baseline; it stands for the Python firmware, which was removed), same plant and stream, same run.
   Lockstep pacing, current mode, 10 kHz, 60 000 samples (quick: 6 000). Twice: with the default plant
   (16 Maxwell-slip elements: the plant dominates) and with a bare inertia (the device's own cost).
2. The highest sample rate the emulated Cortex-M4F (QEMU mps2-an386, realtime image, no -icount: the guest
   clock follows the host's) holds in real time: every repeat (3) of a 2 s stream has 0 lost samples and a
   wall time within REALTIME_STRETCH (1.05x) of nominal; rates are tried upwards and the first that fails
   ends the search. The row's ratio is against the nominal time (1.0 = real time). Quick: skipped
   (tests/firmware runs QEMU). Measured twice: with the default plant (which the image simulates in soft
   double precision, as a board would not) and with a bare inertia (the core's own capacity). Every
   received byte crosses QEMU's one-byte CMSDK UART (one QEMU main-loop pass per byte), so this is a
   property of the emulation on this host. Also the lockstep throughput (samples/s) of the default image:
   the most the emulated link carries when nothing waits for a clock.
3. Flash (text + data) and RAM (data + bss) of the QEMU and Nucleo-F446RE images, from arm-none-eabi-size;
   baseline: the F446RE's 512 KiB flash and 128 KiB RAM.
Parts 2 and 3 need the cross toolchain and QEMU (``make toolchain``); without them they report nothing.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np


def _row(name, value, unit, baseline_name=None, baseline_value=None, target=None, ok=None) -> dict:
    ratio = value / baseline_value if baseline_value else None
    return {"name": name, "value": float(value), "unit": unit, "baseline_name": baseline_name,
            "baseline_value": None if baseline_value is None else float(baseline_value), "ratio": ratio,
            "target": target, "ok": ok}


def _stream_blocks(n: int, max_block: int):
    from hilbench.drivers import protocol as p

    u = (2.0 * np.sin(2 * np.pi * 3.0 * np.arange(n) / 10000)).astype(np.float32)
    return p.make_setpoint_blocks(u, max_block)


def ns_per_sample_c(n: int, sim) -> float:
    from hilbench.drivers import protocol as p
    from hilbench.firmware_sim.devices.core_c import CoreDevice

    dev = CoreDevice(sim, "lockstep", max_block=512)
    frames = [p.encode_frame(b) for b in _stream_blocks(n, 512)]
    dev.rx_bytes(p.encode_frame(p.Config(sample_rate=10000, current_limit=5.0, torque_constant=0.2)), 0.0)
    dev.rx_bytes(p.encode_frame(p.Arm()), 0.0)
    dev.take_bytes()
    t0 = time.perf_counter()
    for i in range(0, len(frames), 8):  # credit: 8 blocks of 512 fit the 8192-sample buffer
        for frame in frames[i: i + 8]:
            dev.rx_bytes(frame, 0.0)
        while dev.busy:
            dev.tick(0.0)
        dev.take_bytes()
    return (time.perf_counter() - t0) / n * 1e9


def ns_per_sample_reference(n: int, sim) -> float:
    """The baseline: the same device work as a plain Python/numpy loop (no state machine), ns per sample.

    Setpoint frames are decoded by the Python codec (COBS, CRC-32), the C plant runs each block through
    ``firmware_sim.engine.plant.Plant`` (the same plant the core drives), the limits are checked with numpy
    (over-current, over-speed over a 1 ms window, position window) and the sample blocks are encoded by the
    Python codec. This is what the removed Python firmware did per block, without its bookkeeping, so the
    ratio is a lower bound of the C core's gain over it.
    """
    from hilbench.drivers import protocol as p
    from hilbench.firmware_sim.engine.plant import Plant

    rate, cpr, limit, v_max = 10000, 4096, 5.0, 1e4
    plant = Plant(sim.plant_for(limit, 0.2, cpr), 1.0 / rate, sim.substeps_at(rate), "current")
    frames = [p.encode_frame(b) for b in _stream_blocks(n, 512)]
    decoder, window, scale = p.FrameDecoder(), rate // 1000, 2.0 * np.pi / cpr
    history = None
    index = seq = 0
    t0 = time.perf_counter()
    for i in range(0, len(frames), 8):
        for blk in decoder.feed(b"".join(frames[i: i + 8])):
            u = blk.values.astype(np.float64)
            res = plant.run(u)
            counts = res.counts.astype(np.int64)
            history = np.full(window, counts[0]) if history is None else history
            hist = np.concatenate((history, counts))
            speed = np.abs(hist[window:] - hist[:-window]) * (scale * rate / window)
            bad = (np.abs(res.current_meas) > limit) | (np.abs(u) > limit) | (speed > v_max) \
                | (np.abs(counts * scale) > 1e9)
            assert not bad.any()  # the stream stays inside the limits: every sample is checked, none trips
            history = hist[-window:]
            status = np.full(len(u), p.SampleStatus.ENABLED, dtype=np.uint16)
            p.encode_frame(p.SampleBlock(seq, index, 8192, index + len(u), 0, p.State.STREAMING,
                                         counts.astype(np.int32), res.current_cmd, res.current_meas, status))
            index, seq = index + len(u), seq + 1
    return (time.perf_counter() - t0) / n * 1e9


def m4_sustains(elf, rate: int, seconds: float) -> tuple[bool, int, float]:
    """Stream ``seconds`` at ``rate`` to the realtime image; (0 lost, lost samples, wall time s)."""
    from hilbench.drivers import protocol as p
    from hilbench.drivers.device_url import open_device
    from hilbench.drivers.errors import DriverError
    from tests.firmware import qemu_target

    n, received, t0 = int(seconds * rate), 0, time.perf_counter()
    with qemu_target.running_qemu(elf) as (_, pty):
        try:
            with open_device(f"serial://{pty}", timeout=5.0) as amp:
                amp.configure(p.Config(sample_rate=rate, current_limit=5.0, torque_constant=0.2,
                                       watchdog_timeout=0.5))
                amp.arm()
                u = 1.0 * np.sin(2 * np.pi * 5.0 * np.arange(n) / rate)
                t0 = time.perf_counter()
                for blk in amp.stream(u, allow_loss=True):
                    received += len(blk)
        except DriverError:  # a fault or a timeout: what did not arrive is lost
            pass
        wall = time.perf_counter() - t0
    lost = n - received
    return lost == 0, lost, wall


def m4_lockstep_rate(elf, n: int) -> float:
    """Samples per second of wall time the lockstep image streams (1 kHz configuration, current mode)."""
    from hilbench.drivers import protocol as p
    from hilbench.drivers.device_url import open_device
    from tests.firmware import qemu_target

    with qemu_target.running_qemu(elf) as (_, pty), open_device(f"serial://{pty}", timeout=5.0) as amp:
        # a heartbeat can wait behind blocks in the emulated link for longer than 0.5 s on a loaded host;
        # the watchdog is not what this measures
        amp.configure(p.Config(sample_rate=1000, current_limit=5.0, torque_constant=0.2, watchdog_timeout=5.0))
        amp.arm()
        t0 = time.perf_counter()
        received = sum(len(b) for b in amp.stream(np.sin(np.arange(n) / 50.0), allow_loss=True))
        return received / (time.perf_counter() - t0)


REALTIME_STRETCH = 1.05  # a stream holds real time when its wall time is within 5 % of its nominal time


def m4_highest_realtime_rate(image, label: str, seconds: float = 2.0, repeats: int = 3) -> tuple[int, float]:
    """(highest protocol rate held in real time, worst wall / nominal there); (0, 0.0) if 1 kHz fails."""
    best, stretch = 0, 0.0
    for rate in (1000, 2000, 5000, 10000, 20000):
        runs = [m4_sustains(image, rate, seconds) for _ in range(repeats)]
        for _, lost, wall in runs:
            print(f"  QEMU M4 {label}, realtime {rate} Hz, {seconds:g} s: lost {lost} samples, wall {wall:.2f} s")
        if not all(ok and wall / seconds <= REALTIME_STRETCH for ok, _, wall in runs):
            break
        best, stretch = rate, max(wall for _, _, wall in runs) / seconds
    return best, stretch


def run(quick: bool = False) -> list[dict]:
    from hilbench.firmware_sim.devices.sim_config import load_sim_config, sim_config_from_dict

    n = 6000 if quick else 60000
    rows = []
    bare = sim_config_from_dict({"plant": {"preset": "none", "inertia": 1e-4, "viscous": 1e-3}})
    for label, sim in (("default plant", load_sim_config()), ("bare inertia", bare)):
        c_ns = ns_per_sample_c(n, sim)
        py_ns = ns_per_sample_reference(n, sim)
        rows.append(_row(f"host, {label}: C core, ns per sample", c_ns, "ns", "Python/numpy reference loop", py_ns))

    from tests.firmware import qemu_target

    if qemu_target.missing_tools():
        return rows
    elf = qemu_target.build_image("realtime")
    board = qemu_target.build_image("nucleo-f446re")
    for name, image in (("QEMU mps2-an386 image (core + plant)", elf), ("Nucleo-F446RE image (core)", board)):
        size = qemu_target.size(image)
        rows.append(_row(f"{name}: flash", size["flash"], "bytes", "F446RE flash", 512 * 1024))
        rows.append(_row(f"{name}: RAM", size["ram"], "bytes", "F446RE RAM", 128 * 1024))
    if quick:
        return rows
    with tempfile.TemporaryDirectory() as tmp:
        toml = Path(tmp) / "bare.toml"
        toml.write_text('[plant]\npreset = "none"\ninertia = 1e-4\nviscous = 1e-3\n')
        bare_elf = qemu_target.build_image("realtime", str(toml), Path(tmp) / "build")
        for label, image in (("default plant", elf), ("bare inertia", bare_elf)):
            best, stretch = m4_highest_realtime_rate(image, label)
            rows.append(_row(f"QEMU M4, {label}: highest real-time rate", best, "Hz", "protocol maximum", 20000))
            rows.append(_row(f"QEMU M4, {label}: wall / nominal there", stretch, "x", "real time", 1.0,
                             target=f"<= {REALTIME_STRETCH}", ok=best > 0))
    rows.append(_row("QEMU M4: lockstep throughput", m4_lockstep_rate(qemu_target.build_image("lockstep"), 4000),
                     "samples/s", "protocol maximum", 20000))
    return rows
