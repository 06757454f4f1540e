"""How every ``ergo`` command reports a user error: one line ``ergo: error: ...`` on stderr and
exit code 2, never a traceback. Here, in the bottom layer, so that the CLI of every package
(robot, vision, sim, calibration, explore) and the scripts of bench/ and experiments/ may use
it; the ``ergo`` root (``explore/cli``) catches ``CliError`` and prints it with ``error``."""

from __future__ import annotations

import sys

#: the exit code of a user error (argparse's own for a bad flag)
USER_ERROR_EXIT = 2


class CliError(Exception):
    """A user error: printed as one line ``ergo: error: ...`` with exit code 2."""


def error(message: object) -> int:
    """Print ``message`` (a string or an exception) as ``ergo: error: MESSAGE`` on stderr, an
    exception's notes after it on the same line (``robot.arm.Arm.disconnect`` adds a failed
    torque-off as one); returns the exit code of a user error (2), for ``return error(...)``."""
    notes = getattr(message, "__notes__", None) if isinstance(message, BaseException) else None
    text = "; ".join([str(message), *map(str, notes or ())])  # what the failure left undone
    print(f"ergo: error: {text}", file=sys.stderr)
    return USER_ERROR_EXIT
