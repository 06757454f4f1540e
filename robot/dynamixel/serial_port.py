"""The serial port under the Dynamixel bus: what the bus needs of one (``SerialLike``) and
opening one by path or pyserial URL (``open_serial``), with a one-line ``BusError`` that says
why it failed."""

from __future__ import annotations

from typing import Any, Protocol

from robot.errors import BusError

# How long one serial read may block while waiting (pyserial timeout), s. Small, so the
# deadline is kept to about this precision; not a protocol figure.
POLL_S = 0.001


class SerialLike(Protocol):
    """What the bus needs of a pyserial ``Serial`` (an in-process fake may stand in)."""

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...

    def flush(self) -> None: ...

    def reset_input_buffer(self) -> None: ...

    def close(self) -> None: ...


def open_serial(port: str, baud: int) -> Any:
    """Open ``port`` (a path or a pyserial URL such as ``loop://``) at ``baud`` with a short
    read timeout; one-line ``BusError`` when that fails."""
    import serial  # pyserial; imported here so that the codec works without it

    try:
        if "://" in port:
            return serial.serial_for_url(port, baudrate=baud, timeout=POLL_S)
        return serial.Serial(port, baudrate=baud, timeout=POLL_S, exclusive=True)
    except ValueError as exc:
        raise BusError(f"cannot open Dynamixel bus {port} at {baud} baud: {exc}") from exc
    except serial.SerialException as exc:
        raise BusError(_explain_open_error(port, baud, exc)) from exc


def _explain_open_error(port: str, baud: int, exc: Exception) -> str:
    text = str(exc)
    errno = getattr(exc, "errno", None)
    if errno == 2 or "No such file" in text:
        why = "no such port (unplugged? check `ls /dev/ttyUSB* /dev/ttyACM*`)"
    elif errno == 13 or "Permission denied" in text:
        why = "permission denied (add your user to the dialout group)"
    elif errno in (11, 16) or "lock" in text or "busy" in text.lower():
        why = "port busy (another program has it open)"
    elif "baud" in text.lower():
        why = f"the port refuses {baud} baud"
    else:
        why = text.splitlines()[0] if text else type(exc).__name__
    return f"cannot open Dynamixel bus {port}: {why}"
