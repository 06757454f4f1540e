"""The one progress bar of ``ergo explore`` and of a campaign's trials."""

from __future__ import annotations

from explore.runs.explorer import Progress
from explore.runs.progress import ProgressBar


def test_the_bar_shows_the_episode_and_the_cells(capsys):
    bar = ProgressBar(10, 2)
    bar.update(Progress(episode=3, total=10, ball_cells=4, ee_cells=5, phase="random",
                        episodes_per_s=2.5))  # fmt: skip
    bar.close()
    err = capsys.readouterr().err
    assert "3/10" in err and "cells=4" in err and "ee=5" in err and "eps=2.5" in err


def test_a_trials_bar_has_its_label_and_no_rates(capsys):
    bar = ProgressBar(10, 0, "rpe s0", 2.0, rates=False)
    bar.update(Progress(episode=1, total=10, ball_cells=7, ee_cells=9, phase="goals",
                        episodes_per_s=3.0))  # fmt: skip
    bar.close()
    err = capsys.readouterr().err
    assert "rpe s0" in err and "cells=7" in err and "phase=goals" in err
    assert "ee=" not in err and "eps=" not in err
