"""plumbing.registry's near-miss hint: the nearest known name, case ignored, or none."""

from __future__ import annotations

from plumbing.registry import did_you_mean, nearest


def test_the_nearest_name_case_ignored():
    names = ["rpe", "rge-efr", "mge-efr"]
    assert nearest("rge-erf", names) == "rge-efr"
    assert nearest("RGE-EFR", names) == "rge-efr"  # the name as it is spelt, not as typed
    assert did_you_mean("Rge-Efr", names) == " (did you mean 'rge-efr'?)"
    assert nearest("zzz", names) is None and did_you_mean("zzz", names) == ""


def test_names_that_differ_by_case_alone_give_the_first():
    assert nearest("SIM", ["sim", "Sim"]) == "sim"
