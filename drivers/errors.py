"""The host's exception tree: everything `drivers` raises about a tracker derives from `TrackerError`.

    TrackerError                          anything that went wrong talking to a tracker
     ├── LinkError (OSError)              the link could not be opened, or failed/closed while in use
     │    └── SchemeUnavailableError      unknown URL scheme, or its module is missing
     ├── TrackerTimeoutError (TimeoutError)   no response (after retries), or no sample within the timeout
     ├── CommandRefusedError              the device answered ERROR: `code` (protocols.ErrorCode), `text`
     ├── IncompatibleDeviceError          no common protocol version, or a capability the host needs is missing
     └── CalibrationError                 too few usable samples, or the estimator could not fit

Faults on the wire (CRC errors, lost frames, malformed frames) are not exceptions: the client counts
them (`eyehil.drivers.client.HostStats`) and goes on, as the protocol's receiver rules require. Malformed
recording files raise `eyehil.drivers.recording.RecordingError` (a ValueError), not a TrackerError.
"""

from __future__ import annotations

from eyehil.protocols.errors import ErrorCode


class TrackerError(Exception):
    """Base of every error about a tracker."""


class LinkError(TrackerError, OSError):
    """The link could not be opened, or failed while in use."""


class SchemeUnavailableError(LinkError):
    """The URL scheme is unknown or its implementation is not installed."""


class TrackerTimeoutError(TrackerError, TimeoutError):
    """Nothing (or not the expected response) arrived in time."""


class CommandRefusedError(TrackerError):
    """The device answered a command with ERROR."""

    def __init__(self, command: str, code: int, text: str) -> None:
        name = ErrorCode(code).name if code in ErrorCode._value2member_map_ else f"0x{code:02X}"
        super().__init__(f"{command} refused: {name} {text}".rstrip())
        self.command, self.code, self.text = command, code, text


class IncompatibleDeviceError(TrackerError):
    """The device cannot serve this host (protocol version, capabilities)."""


class CalibrationError(TrackerError):
    """Calibration through the device failed."""
