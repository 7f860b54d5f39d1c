"""``hilbench info --device URL``: identity, configuration, faults and counters of a device."""

from __future__ import annotations

import math


def register(subparsers) -> None:
    parser = subparsers.add_parser("info",
                                   help="show a device's identity, configuration, faults and counters",
                                   description="Connect to a device, print what it reports, disconnect "
                                               "(closing disarms it).")
    from hilbench.drivers.device_url import describe_schemes

    parser.add_argument("--device", default=None,
                        help=f"device URL: {describe_schemes()} (default $HILBENCH_DEVICE, the config file's "
                             "'device', else sim://)")
    parser.set_defaults(func=run)


def describe(amp) -> list[str]:
    """Lines describing an :class:`drivers.amplifier.Amplifier` (units in every line)."""
    from hilbench.drivers import protocol as p

    if amp.clock == "host":  # an off-the-shelf drive: what it reports about itself, and what it can run
        faults = amp.faults()
        return [f"{k}: {v}" for k, v in amp.info().items()] + [
            f"state: {amp.state()}", f"faults: {'; '.join(faults) if faults else 'none'}", *amp.history(),
            f"clock: host-clocked; runs {amp.capabilities.describe()}"]
    ident = amp.identity
    status = amp.status()
    lines = [
        f"model: {ident.model}",
        f"serial: {ident.serial}",
        f"firmware: {ident.firmware}",
        f"protocol version: {ident.protocol_version}",
        f"setpoint buffer: {ident.buffer_capacity} samples (blocks up to {ident.max_block})",
        "sensors: " + (", ".join(s.name.lower() for s in p.Sensor if s & ident.sensors) or "none")
        + (" (winding temperature in every sample block, degC)" if ident.sensors & p.Sensor.TEMPERATURE else ""),
        f"state: {p.State(status.state).name}",
        f"faults: {p.describe_faults(status.faults)}"
        + (f" (first at sample {status.fault_index})" if status.faults else ""),
        f"sample index: {status.index}",
        f"current applied: {status.current_applied:.6g} A",
        f"counters: crc_errors={status.crc_errors} dropped_frames={status.dropped_frames} "
        f"rx_frames={status.rx_frames} tx_frames={status.tx_frames}",
        "host counters: " + " ".join(f"{k.removeprefix('host_')}={v}" for k, v in amp.counters.items()
                                     if k.startswith("host_"))
        + " (crc_errors: malformed frames counted and dropped)",
    ]
    cfg = amp.config
    if cfg is None:
        lines.append("config: not configured")
    else:
        window = "off" if math.isinf(cfg.position_min) and math.isinf(cfg.position_max) else \
            f"[{cfg.position_min:.6g}, {cfg.position_max:.6g}] rad"
        watchdog = f"{cfg.watchdog_timeout:.6g} s" if cfg.watchdog_timeout > 0 else "off"
        lines += [
            f"sample rate: {cfg.sample_rate} Hz",
            f"mode: {p.Mode(cfg.mode).name.lower()}",
            f"current limit: {cfg.current_limit:.6g} A",
            f"velocity limit: {cfg.velocity_limit:.6g} rad/s",
            f"position window: {window}",
            f"watchdog: {watchdog}",
            f"torque constant: {cfg.torque_constant:.6g} N*m/A",
            f"encoder: {cfg.counts_per_rev} counts/rev",
            f"ratio: {cfg.ratio:.6g} motor rev per load rev",
        ]
    return lines


def run(args) -> int:
    from hilbench.drivers.device_url import open_device

    with open_device(args.device) as amp:
        for line in describe(amp):
            print(line)
    return 0
