"""The one way a JSON-like object read from a file or a command line is checked: ``Fields``,
whose every failure is one line ``WHERE: field 'PATH' WHY`` raised as the caller's error class
(``calibration.store.CalibrationError``, ``explore.runs.config.RunConfigError``), and the
predicates it is made of (``is_int``, ``is_number``, ``is_matrix``), which the typed options of
``explore/options.py`` use too. In ``robot/``, the bottom layer, so that every package may
use it (docs/architecture.md)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any, NoReturn

from plumbing.registry import did_you_mean


def is_int(v: Any) -> bool:
    """An integer, not a bool (JSON's true is not 1)."""
    return isinstance(v, int) and not isinstance(v, bool)


def is_number(v: Any) -> bool:
    """A finite number (int or float), not a bool."""
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def is_matrix(v: Any, shape: tuple[int, ...]) -> bool:
    """Whether ``v`` is nested lists of finite numbers of this shape (-1: any length >= 1)."""
    if not shape:
        return is_number(v)
    if not isinstance(v, list) or not v:
        return False
    if shape[0] >= 0 and len(v) != shape[0]:
        return False
    return all(is_matrix(x, shape[1:]) for x in v)


class Fields:
    """Checks of the fields of one object.

    Args:
        where: what holds it, for the start of the line (a file's path, "command line").
        data: the object; anything but a dict fails at once.
        error: the exception class raised (one argument: the line).
        path: the object's own path in the document ("config", "config.rig"; "" for the top:
            the fields are then named alone).
        name: what the object is called when it is not an object at all (default ``path``).
        label: how the line names a field from its full path (default ``field 'PATH'``): a
            command line names its flags instead (``explore.runs.config.flag_of``). With an
            empty ``where`` the line starts with the label.
    """

    def __init__(
        self,
        where: str,
        data: Any,
        error: type[Exception] = ValueError,
        path: str = "",
        name: str | None = None,
        label: Callable[[str], str] | None = None,
    ) -> None:
        self.where = where
        self.error = error
        self.path = path
        self.label = label or (lambda full: f"field '{full}'")
        if not isinstance(data, dict):
            self._raise(name or path, f"must be an object, got {type(data).__name__}")
        self.data: dict[str, Any] = data

    def _raise(self, full: str, why: str) -> NoReturn:
        where = f"{self.where}: " if self.where else ""
        raise self.error(f"{where}{self.label(full)} {why}")

    def name_of(self, name: str) -> str:
        """The full path of the field ``name``."""
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, why: str) -> NoReturn:
        """Raise the line for field ``name``: ``WHERE: field 'PATH.NAME' WHY``."""
        self._raise(self.name_of(name), why)

    def get(self, name: str, optional: bool = False) -> Any:
        """The field's value; a missing one fails ("is missing") unless ``optional`` (None)."""
        if name not in self.data:
            if optional:
                return None
            self.fail(name, "is missing")
        return self.data[name]

    def only(self, known: Iterable[str]) -> None:
        """Fail on the first key (sorted) that is not in ``known``."""
        known = list(known)
        unknown = sorted(set(self.data) - set(known))
        if unknown:
            self.fail(unknown[0], f"is unknown; known: {', '.join(known)}")

    def sub(self, name: str) -> Fields:
        """The fields of the object at ``name`` (which must be there, and be an object)."""
        v = self.get(name)
        if not isinstance(v, dict):
            self.fail(name, f"must be an object, got {type(v).__name__} {v!r}")
        return Fields(self.where, v, self.error, self.name_of(name), label=self.label)

    def number(
        self, name: str, lo: float = -math.inf, hi: float = math.inf, optional: bool = False
    ) -> Any:
        """A finite number in [lo, hi]."""
        v = self.get(name, optional)
        if v is None and optional:
            return None
        bounded = not (lo == -math.inf and hi == math.inf)
        if not is_number(v) or not lo <= v <= hi:
            in_range = f" in [{lo:g}, {hi:g}]" if bounded else ""
            self.fail(name, f"must be a finite number{in_range}, got {v!r}")
        return v

    def integer(
        self, name: str, lo: float = -math.inf, hi: float = math.inf, optional: bool = False
    ) -> Any:
        """An integer in [lo, hi]."""
        v = self.get(name, optional)
        if v is None and optional:
            return None
        if not is_int(v) or not lo <= v <= hi:
            if hi == math.inf:
                in_range = "" if lo == -math.inf else f" >= {lo:g}"
            else:
                in_range = f" in [{lo:g}, {hi:g}]"
            self.fail(name, f"must be an integer{in_range}, got {v!r}")
        return v

    def string(self, name: str, optional: bool = False) -> Any:
        """A non-empty string."""
        v = self.get(name, optional)
        if v is None and optional:
            return None
        if not isinstance(v, str) or not v:
            self.fail(name, f"must be a non-empty string, got {v!r}")
        return v

    def one_of(self, name: str, table: Iterable[str]) -> str:
        """A string among ``table``'s names (a mistyped one gets the nearest as a hint)."""
        names = sorted(table)
        v = self.data.get(name)
        if not isinstance(v, str) or v not in names:
            self.fail(name, f"must be one of {', '.join(names)}, got {v!r}{did_you_mean(v, names)}")
        return v

    def matrix(self, name: str, shape: tuple[int, ...], optional: bool = False) -> Any:
        """Nested lists of finite numbers of ``shape`` (-1: any length >= 1)."""
        v = self.get(name, optional)
        if v is None and optional:
            return None
        if not is_matrix(v, shape):
            dims = "x".join("N" if s < 0 else str(s) for s in shape)
            self.fail(name, f"must be a {dims} array of finite numbers")
        return v
