"""The ``ergo`` command. Each package contributes its subcommands through a ``register``
function in its own ``cli`` module (listed below); this root only assembles them."""

from __future__ import annotations

import argparse
import errno
import logging
import sys
from typing import Any

from plumbing.cli_errors import CliError, error
from plumbing.registry import LazyTable, RegistryError, did_you_mean

# Each package's ``register(subparsers) -> None``, in the order of ``ergo --help``. Each module
# must import quickly (no torch or MuJoCo at module level) so that ``ergo --help`` stays fast.
COMMAND_MODULES = LazyTable(
    "command module",
    {
        "explore": "explore.cli.explore:register",
        "sim": "sim.cli:register",
        "robot": "robot.cli:register",
        "vision": "vision.cli:register",
        "calibration": "calibration.cli:register",
        "experiment": "explore.cli.experiment:register",
        "report": "explore.cli.report:register",
        "runs": "explore.cli.runs:register",
        "export": "explore.cli.export:register",
    },
)


class OneLineParser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage dump) for bad flags."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        """argparse's check of a value against ``choices`` (commands too), with the hint for a
        mistyped one (Python 3.14's argparse has its own; this one works from 3.11)."""
        if action.choices is not None and value not in action.choices:
            choices = ", ".join(map(repr, action.choices))
            raise argparse.ArgumentError(
                action,
                f"invalid choice: {value!r}{did_you_mean(value, action.choices)} "
                f"(choose from {choices})",
            )


def _user_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that are the user's input or the hardware's state, not bugs: one line."""
    from robot.errors import RobotError
    from vision.camera import CameraError

    return (CliError, RegistryError, RobotError, CameraError, FileNotFoundError, PermissionError)


# What the file system says when it cannot do what a command asked (full, read-only, a loop of
# links, a file where a folder should be): the machine's state, not a bug: one line naming the
# file. Commands that can keep what they stored say more themselves.
FILE_SYSTEM_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.ELOOP, errno.ENOTDIR,
     errno.EISDIR, errno.EIO, errno.ENAMETOOLONG}
)  # fmt: skip


def describe_os_error(exc: OSError) -> str:
    """``OSError`` in one line: what failed and on which file."""
    what = exc.strerror or str(exc)
    where = f": {exc.filename}" if exc.filename else ""
    hint = " (a full disk: free some space and run the command again)" if exc.errno in (
        errno.ENOSPC, errno.EDQUOT) else ""  # fmt: skip
    return f"{what}{where}{hint}"


def version() -> str:
    """The installed version of ergo-explore (its package metadata), or "unknown" when the
    source runs without being installed."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as package_version

    try:
        return package_version("ergo-explore")
    except PackageNotFoundError:
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="ergo",
        description="Intrinsically motivated goal exploration on a Poppy Ergo Jr and its twin.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    parser.add_argument("--version", action="version", version=f"ergo-explore {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        register = COMMAND_MODULES.load(name, missing_ok=True)
        if register is not None:  # else that package has no commands in this version
            register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    for pkg in ("robot", "vision", "explore", "sim", "calibration"):
        logging.getLogger(pkg).setLevel(logging.DEBUG if args.verbose else logging.INFO)
    try:
        return int(args.func(args) or 0)
    except _user_errors() as exc:
        return error(exc)
    except OSError as exc:
        if exc.errno not in FILE_SYSTEM_ERRNOS:
            raise
        return error(describe_os_error(exc))
    except KeyboardInterrupt:
        print("ergo: interrupted", file=sys.stderr)
        return 130
