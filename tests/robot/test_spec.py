"""The safety clamp every command goes through: joint limits and the maximum step."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robot.spec import ergo_jr_spec

SPEC = ergo_jr_spec()
wild = arrays(np.float64, (6,), elements=st.floats(-20, 20))


@settings(max_examples=300, deadline=None)
@given(wild, wild)
def test_clamp_never_leaves_limits_or_exceeds_max_step(target, previous):
    prev = np.clip(previous, SPEC.lower, SPEC.upper)
    out = SPEC.clamp(target, prev)
    assert np.all(out >= SPEC.lower) and np.all(out <= SPEC.upper)
    assert np.all(np.abs(out - prev) <= SPEC.max_step + 1e-12)


def test_clamp_refuses_nan_and_wrong_shape():
    with pytest.raises(ValueError, match="non-finite"):
        SPEC.clamp(np.array([0, 0, np.nan, 0, 0, 0]), None)
    with pytest.raises(ValueError, match="shape"):
        SPEC.clamp(np.zeros(5), None)
