"""Typed options: a JSON-like dict (``--rig-option``, ``--strategy-option``, ``run.json``) read
into a frozen dataclass, with one-line errors naming the option and what was expected.

Each rig and each strategy declares its options as a dataclass (field types and defaults);
``parse_options(Options, given, where)`` refuses unknown keys with the list of known ones and
values of the wrong type (by the predicates of ``plumbing.fields``, which also checks
``run.json``'s config and the calibration files). The field types understood are ``bool``,
``int``, ``float``, ``str``, ``Literal[...]``, ``tuple[T, ...]`` and ``tuple[T, T]`` of those,
and unions of them with ``None`` (a JSON list becomes a tuple). A field's
``metadata={"expected": "..."}`` words what a value must be when the type alone says too
little. Range checks belong to the dataclass's ``__post_init__``, which raises
``BadOption(key, reason)``. Only the keys given are checked: the dict keeps the options as
given (``run.json`` stores them so), the dataclass holds them with the defaults.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

from plumbing.fields import is_int, is_number
from plumbing.registry import did_you_mean

T = TypeVar("T")


class OptionsError(ValueError):
    """An option is unknown or has a bad value; the message is one line.

    Attributes:
        key: the option (None when the options are not an object).
        reason: what is wrong with it, e.g. "must be an integer, got 'ten'".
    """

    def __init__(self, where: str, key: str | None, reason: str) -> None:
        prefix = f"{where}: option {key} " if key else f"{where}: options "
        super().__init__(prefix + reason)
        self.key = key
        self.reason = reason


class BadOption(ValueError):
    """Raised by an options dataclass's ``__post_init__``: ``key`` has a value out of range."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"option {key} {reason}")
        self.key = key
        self.reason = reason


def known_options(cls: type) -> list[str]:
    """The option names of an options dataclass, sorted."""
    return sorted(f.name for f in dataclasses.fields(cls))


def parse_options(cls: type[T], given: Any, where: str) -> T:
    """``cls(**given)`` with every value checked (and lists made tuples); see the module doc.

    Raises:
        OptionsError: options that are not an object, an unknown key, a value that is not of
        its field's type or out of its range.
    """
    if given is None:
        given = {}
    if not isinstance(given, dict):
        raise OptionsError(where, None, f"must be an object, got {type(given).__name__}")
    known = known_options(cls)
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise OptionsError(
            where,
            unknown[0],
            f"is unknown{did_you_mean(unknown[0], known)}; known: {', '.join(known)}",
        )
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    values = {}
    for key, value in given.items():
        ok, converted = _convert(hints[key], value)
        if not ok:
            expected = fields[key].metadata.get("expected") or _describe(hints[key])
            hint = did_you_mean(value, get_args(hints[key])) if isinstance(value, str) else ""
            raise OptionsError(where, key, f"must be {expected}, got {value!r}{hint}")
        values[key] = converted
    try:
        return cls(**values)
    except BadOption as exc:
        raise OptionsError(where, exc.key, exc.reason) from None


def _convert(kind: Any, value: Any) -> tuple[bool, Any]:
    origin, args = get_origin(kind), get_args(kind)
    if origin in (Union, types.UnionType):
        for arg in args:
            ok, converted = _convert(arg, value)
            if ok:
                return True, converted
        return False, None
    if origin is Literal:
        return (any(value == a and type(value) is type(a) for a in args), value)
    if origin is tuple:
        if not isinstance(value, list | tuple):
            return False, None
        items = list(value)
        if len(args) == 2 and args[1] is Ellipsis:
            item_kinds = [args[0]] * len(items)
        elif len(args) != len(items):
            return False, None
        else:
            item_kinds = list(args)
        out = []
        for item_kind, item in zip(item_kinds, items, strict=True):
            ok, converted = _convert(item_kind, item)
            if not ok:
                return False, None
            out.append(converted)
        return True, tuple(out)
    if kind is type(None):
        return value is None, None
    if kind is bool:
        return isinstance(value, bool), value
    if kind is int:
        return is_int(value), value
    if kind is float:
        return (True, float(value)) if is_number(value) else (False, None)
    if kind is str:
        return isinstance(value, str) and value != "", value
    raise TypeError(f"options of type {kind!r} are not supported")


def _describe(kind: Any) -> str:
    origin, args = get_origin(kind), get_args(kind)
    if origin in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_describe(args[0])}s"
        return "a list [" + ", ".join(_describe(a) for a in args) + "]"
    return {
        type(None): "null",
        bool: "true or false",
        int: "an integer",
        float: "a number",
        str: "a non-empty string",
    }.get(kind, str(kind))
