"""The ``ergo`` command. Each package contributes its subcommands through a ``register``
function in its own ``cli`` module (listed below); this root only assembles them."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

# Modules with ``register(subparsers) -> None``. Each must import quickly (no torch or MuJoCo at
# module level) so that ``ergo --help`` stays fast.
COMMAND_MODULES = (
    "explore.cli_explore",
    "sim.cli",
    "robot.cli",
    "vision.cli",
    "calibration.cli",
    "explore.cli_experiment",
    "explore.cli_report",
)


class CliError(Exception):
    """A user error: printed as one line ``ergo: error: ...`` with exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ergo",
        description="Intrinsically motivated goal exploration on a Poppy Ergo Jr and its twin.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue  # that package has no commands yet
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"ergo: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ergo: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
