"""The metric's grid at its edges: every point of the closed square counts, to the last ulp."""

from __future__ import annotations

import numpy as np
import pytest

from explore.runs.metrics import CellCounter


@pytest.mark.parametrize("half_width", [0.2, 1.0])  # the twin's arena, ArmBalls' square
def test_a_point_an_ulp_inside_the_far_edge_is_in_the_last_cell(half_width):
    c = CellCounter(half_width, 30)
    inside = np.nextafter(half_width, 0.0)  # 0.19999999999999998, 0.9999999999999999
    assert c.cells_of(np.array([inside, 0.0])).tolist() == [[29, 15]]
    assert c.cells_of(np.array([0.0, inside])).tolist() == [[15, 29]]
    assert c.cells_of(np.array([inside, inside])).tolist() == [[29, 29]]
    assert c.add(np.array([[inside, 0.0], [-half_width, -half_width]])) == 2


@pytest.mark.parametrize("half_width", [0.2, 1.0])
def test_the_edges_belong_to_the_square_and_an_ulp_beyond_does_not(half_width):
    c = CellCounter(half_width, 30)
    h = half_width
    edges = np.array([[-h, -h], [h, h], [-h, h], [np.nextafter(-h, 0.0), 0.0]])
    assert c.cells_of(edges).tolist() == [[0, 0], [29, 29], [0, 29], [0, 15]]
    beyond = np.array([[np.nextafter(h, 2 * h), 0.0], [0.0, np.nextafter(-h, -2 * h)]])
    assert c.cells_of(beyond).shape == (0, 2)
    assert c.cells_of(np.array([[np.nan, 0.0], [np.inf, 0.0]])).shape == (0, 2)
