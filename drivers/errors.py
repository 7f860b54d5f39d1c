"""Error types of the device link."""


class DriverError(Exception):
    """Base class of every error the drivers raise."""


class ProtocolError(DriverError):
    """Bytes that are not a valid frame or message of the wire protocol (the decoder's only error)."""


class LinkClosedError(DriverError):
    """The link went away (port closed, device unplugged, simulator exited)."""


class PortBusyError(LinkClosedError):
    """The device port is owned by another program (opened exclusively); nothing was sent to the device."""


class DeviceTimeoutError(DriverError, TimeoutError):
    """The device did not answer within the timeout."""


class DeviceFaultError(DriverError):
    """The device latched a fault (or refused a command because one is latched).

    ``faults`` holds the latched :class:`drivers.protocol.Fault` bits.
    """

    def __init__(self, message: str, faults: int = 0) -> None:
        super().__init__(message)
        self.faults = faults


class SampleLossError(DriverError):
    """Samples the device produced never reached the host (frames lost or damaged on the link)."""


class CommandRefusedError(DriverError):
    """The device refused a command (not configured, wrong state, invalid configuration)."""


class ConfigError(DriverError, ValueError):
    """A configuration the host refuses to send (bad sample rate, limit, calibration)."""


class SetpointError(DriverError, ValueError):
    """Setpoints the host refuses to send (NaN, beyond the configured limit, wrong shape)."""


class DeviceURLError(DriverError, ValueError):
    """A device URL that :func:`drivers.open_device` cannot parse."""
