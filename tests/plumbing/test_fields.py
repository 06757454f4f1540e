"""plumbing.fields.Fields: every failure one line ``WHERE: field 'PATH' WHY``, of the caller's
error class, naming the first bad field."""

from __future__ import annotations

import pytest

from plumbing.fields import Fields, is_int, is_matrix, is_number


class Bad(ValueError):
    pass


def _line(call) -> str:
    with pytest.raises(Bad) as info:
        call()
    text = str(info.value)
    assert "\n" not in text
    return text


def test_the_line_names_where_and_the_full_path_of_the_field():
    top = Fields("run.json", {"rig": {"name": 3}, "seed": -1}, Bad, "config")
    assert _line(lambda: top.sub("rig").one_of("name", ["sim", "armballs"])) == (
        "run.json: field 'config.rig.name' must be one of armballs, sim, got 3"
    )
    assert _line(lambda: top.integer("seed", 0)) == (
        "run.json: field 'config.seed' must be an integer >= 0, got -1"
    )
    assert "'config.strategy' is missing" in _line(lambda: top.sub("strategy"))
    assert "'config.seed' is unknown; known: rig" in _line(lambda: top.only(["rig"]))
    assert _line(lambda: Fields("f", [1], Bad, "config")) == (
        "f: field 'config' must be an object, got list"
    )


def test_numbers_strings_and_arrays():
    f = Fields("camera.json", {"rms": 200.0, "k": [[1, 2], [3]], "s": "", "x": float("nan")}, Bad)
    assert _line(lambda: f.number("rms", 0.0, 100.0)) == (
        "camera.json: field 'rms' must be a finite number in [0, 100], got 200.0"
    )
    assert "'x' must be a finite number, got nan" in _line(lambda: f.number("x"))
    assert "'k' must be a 2x2 array of finite numbers" in _line(lambda: f.matrix("k", (2, 2)))
    assert "'s' must be a non-empty string" in _line(lambda: f.string("s"))
    assert f.number("missing", optional=True) is None
    g = Fields("x", {"name": "armball"}, Bad)
    assert "(did you mean 'armballs'?)" in _line(lambda: g.one_of("name", ["armballs", "sim"]))


def test_the_predicates_refuse_bools_and_non_finite_numbers():
    assert is_int(3) and not is_int(True) and not is_int(3.0)
    assert is_number(2.5) and not is_number(False) and not is_number(float("inf"))
    assert is_matrix([[1, 2]], (1, 2)) and is_matrix([1, 2, 3], (-1,))
    assert not is_matrix([], (-1,)) and not is_matrix([[1, True]], (1, 2))


def test_a_label_names_the_field_as_the_caller_does_down_every_sub_object():
    """A command line names its flags (``explore.runs.config.flag_of``); with no ``where``
    the line starts with the label."""
    top = Fields("", {"rig": {"options": {"size": 0}}}, Bad, "config", label=lambda p: f"<{p}>")
    rig = top.sub("rig").sub("options")
    assert (
        _line(lambda: rig.integer("size", 1))
        == "<config.rig.options.size> must be an integer >= 1, got 0"
    )
