"""The progress bar of an exploration on stderr (tqdm), fed with the explorer's ``Progress``
after every stored episode: ``ergo explore``'s and each campaign trial's."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from explore.runs.explorer import Progress


class ProgressBar:
    """A tqdm bar of episodes.

    Args:
        total: episodes the run will have.
        initial: episodes it has already (a resumed run).
        desc: the bar's label (a campaign trial's strategy and seed), None for none.
        mininterval_s: seconds between two redraws at least.
        rates: also show the end-effector cells and the episodes per second (one run in a
            terminal; a campaign's many bars show the ball cells and the phase only).
    """

    def __init__(
        self,
        total: int,
        initial: int,
        desc: str | None = None,
        mininterval_s: float = 1.0,
        rates: bool = True,
    ) -> None:
        from tqdm import tqdm

        self.rates = rates
        self.bar = tqdm(
            total=total, initial=initial, unit="ep", mininterval=mininterval_s, desc=desc,
            file=sys.stderr,
        )  # fmt: skip

    def update(self, p: Progress) -> None:
        self.bar.n = p.episode
        if self.rates:
            self.bar.set_postfix(
                cells=p.ball_cells, ee=p.ee_cells, phase=p.phase, eps=f"{p.episodes_per_s:.1f}",
                refresh=False,
            )  # fmt: skip
        else:
            self.bar.set_postfix(cells=p.ball_cells, phase=p.phase, refresh=False)
        self.bar.update(0)

    def close(self) -> None:
        self.bar.close()
