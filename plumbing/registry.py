"""Tables of name -> ``"module:attr"``, imported only when a name is used (python-can's style
for its interfaces): a user without a CAN adapter library never imports it, and ``ergo --help``
stays fast. Every package's table is a ``LazyTable``: the rigs, the strategies, the campaign
backends, the ``ergo`` command modules, the bus scanners, the bus servers and the arm backends.

``LazyTable.load(name)`` raises one error, with one line that names what is missing and how to
install it: an unknown name lists the known ones; a Python package that is not installed is
named with its install command (``INSTALL``).

This sits in ``robot/`` because every package of the project may import ``robot`` and none of
the others (docs/architecture.md); it imports nothing of the project.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

# Import name of an optional or heavy dependency -> how to install it.
INSTALL: dict[str, str] = {
    "can": "pip install python-can",
    "canopen": "pip install canopen",
    "serial": "pip install pyserial",
    "ray": "pip install 'ergo-explore[ray]'",
    "torch": "pip install torch==2.13.0 (the CPU build, as the Makefile does)",
    "cv2": "pip install opencv-python-headless",
    "mujoco": "pip install mujoco",
    "rerun": "pip install rerun-sdk",
    "matplotlib": "pip install matplotlib",
    "scipy": "pip install scipy",
    "tqdm": "pip install tqdm",
    "pyarrow": "pip install 'ergo-explore[export]'",
    "av": "pip install 'ergo-explore[export]'",
    "gymnasium": "pip install 'ergo-explore[gym]'",
}


def nearest(name: object, choices: Iterable[object]) -> str | None:
    """The known name closest to a mistyped one (difflib's similarity ratio at least 0.6, its
    default), or None when none is close. Case is ignored: ``RGE-EFR`` gives ``rge-efr``."""
    import difflib

    names = {str(c).casefold(): str(c) for c in reversed(list(choices))}
    close = difflib.get_close_matches(str(name).casefold(), names, n=1)
    return names[close[0]] if close else None


def did_you_mean(name: object, choices: Iterable[object]) -> str:
    """`` (did you mean 'X'?)`` for ``nearest(name, choices)``, or "" when none is close: the
    hint every "must be one of" message of the project appends (strategies, rigs, presets,
    options, the choices of ``ergo``'s flags, run folders, CAN interfaces)."""
    close = nearest(name, choices)
    return f" (did you mean {close!r}?)" if close is not None else ""


class RegistryError(LookupError):
    """A name is not in its table, or what it names cannot be imported (one line)."""


class LazyTable(Mapping[str, str]):
    """name -> ``"module:attr"`` (or ``"module"`` for the module itself), loaded on demand.

    Args:
        kind: what the names are, for messages ("rig", "strategy", ...).
        entries: name -> target.
        error: the exception class ``load`` raises (a package's own error type, so that its
            callers catch one type); its message is always this module's.
    """

    def __init__(
        self, kind: str, entries: Mapping[str, str], error: type[Exception] = RegistryError
    ) -> None:
        self.kind = kind
        self._entries = dict(entries)
        self.error = error

    def __getitem__(self, name: str) -> str:
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def unknown(self, name: object) -> Exception:
        """The error for a name that is not in the table."""
        return self.error(
            f"unknown {self.kind} {name!r}{did_you_mean(name, self)}; "
            f"choose one of {', '.join(self)}"
        )

    def load(self, name: str, missing_ok: bool = False) -> Any:
        """Import what ``name`` stands for and return it.

        Args:
            missing_ok: return None instead of raising when the target's own module does not
                exist (a package that has no such part in this version).

        Raises:
            ``self.error`` (``RegistryError`` by default): unknown name, a dependency that is
            not installed (with its install command), or a missing module or attribute.
        """
        target = self._entries.get(name)
        if target is None:
            raise self.unknown(name)
        module_name, _, attr = target.partition(":")
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            missing = exc.name or ""
            if missing == module_name or module_name.startswith(missing + "."):
                if missing_ok:
                    return None
                raise self.error(
                    f"{self.kind} {name!r} is not available in this version "
                    f"(no module {module_name})"
                ) from None
            top = missing.split(".")[0]
            hint = INSTALL.get(top)
            raise self.error(
                f"{self.kind} {name!r} needs the Python package {top!r}, which is not installed"
                + (f": {hint}" if hint else "")
            ) from None
        except ImportError as exc:
            raise self.error(f"{self.kind} {name!r} could not be imported: {exc}") from exc
        if not attr:
            return module
        found = getattr(module, attr, None)
        if found is None:
            raise self.error(
                f"{self.kind} {name!r} is not available in this version ({target} is missing)"
            )
        return found
