"""The twin renders in a process forked after it rendered (multiprocessing's default on Linux):
the child makes its own renderers and never touches the parent's, and the parent keeps its own."""

from __future__ import annotations

import multiprocessing

import numpy as np

import sim.twin
from sim.twin import Twin

SIDE = 32


def _render_in_child(twin: Twin, inherited: object, queue) -> None:
    image = twin.render(size=(SIDE, SIDE))
    queue.put(
        {
            "image": image,
            "own_renderer": twin._renderers[(SIDE, SIDE)] is not inherited,
            "set_aside": any(r is inherited for r in sim.twin._INHERITED_RENDERERS),
        }
    )
    twin.close()  # frees the child's renderer only


def test_a_forked_child_renders_with_its_own_renderers():
    twin = Twin()
    try:
        before = twin.render(size=(SIDE, SIDE))
        inherited = twin._renderers[(SIDE, SIDE)]
        ctx = multiprocessing.get_context("fork")
        queue = ctx.Queue()
        child = ctx.Process(target=_render_in_child, args=(twin, inherited, queue))
        child.start()
        try:
            got = queue.get(timeout=60)  # a hang in the child fails here instead of blocking
        finally:
            child.join(10)
            if child.is_alive():
                child.kill()
        assert child.exitcode == 0
        assert got["own_renderer"] and got["set_aside"]
        np.testing.assert_array_equal(got["image"], before)
        assert twin._renderers[(SIDE, SIDE)] is inherited  # the parent's untouched
        np.testing.assert_array_equal(twin.render(size=(SIDE, SIDE)), before)
    finally:
        twin.close()
