"""An outcome dataset made from a run: the outcome images its episodes recorded, for training a
representation on the rig's own view (``ergo dataset outcomes --run RUN``; then ``ergo sae
train`` / ``ergo vae train``, as on the twin's rendered database). The paper's database,
gathered by the arm itself: an RPE run over a bus, say.

The run is read, never changed (``explore.runs.store.read_history``: no repair, no lock taken;
a torn last record is left out, as a reader of a run being written sees it). Each record's
``image`` is the observation the rig made after the episode, with the arm back at rest: on a
physical rig with an arena calibration the twin's view of the camera's frame
(``explore.rigs.ball.CameraSensor``), the same picture the twin renders. A physical rig's run
made without an arena calibration recorded the raw frame's centre square instead, which no
model of the twin's view can share: it is refused.

Arrays written (``explore.rigs.sim_dataset.save_dataset``): ``images`` (n, S, S, 3) BGR uint8,
``ball`` (n, 2) the ball after each episode (the rig's unit, NaN where the tracker did not see
it), ``context_ball`` (n, 2) before it, ``episode`` (n,) the run's episode numbers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from explore.runs.layout import INPUTS_KEY
from explore.runs.store import RunStoreError, read_history


class DatasetError(RunStoreError):
    """A run whose images cannot make a dataset (one line)."""


def check_images_are_views(run: Path, meta: dict) -> None:
    """Refuse a physical rig's run that recorded no arena calibration among its inputs: its
    images are the camera frame's centre square, not the arena seen from above."""
    from explore.rigs.rig import RigError, is_physical

    rig = meta.get("config", {}).get("rig", {})
    name = str(rig.get("name", "sim"))
    try:
        physical = is_physical(name)
    except RigError as exc:
        raise DatasetError(f"{run}: {exc}") from None
    kinds = {entry.get("kind") for entry in meta.get(INPUTS_KEY) or []}
    if physical and "arena" not in kinds:
        rig_id = rig.get("rig_id", "ID")
        raise DatasetError(
            f"{run}: a run of rig {name!r} without an arena calibration recorded the camera "
            f"frame's centre square, not the arena seen from above: calibrate the arena (ergo "
            f"calibrate arena --rig-id {rig_id} --camera ...) and make the run again"
        )


def run_outcome_dataset(run: str | Path, n: int | None = None) -> dict[str, np.ndarray]:
    """The outcome images of ``run``'s first ``n`` episodes (all: None) and where the ball was
    (module docstring); a ``RunStoreError`` (one line) for a folder that is not a run, a run
    with no episode, or one whose images are not the twin's view."""
    run = Path(run)
    history = read_history(run)
    check_images_are_views(run, history.meta)
    records = history.records if n is None else history.records[:n]
    if not records:
        raise DatasetError(f"{run}: the run holds no episode: no outcome image to make a dataset")
    return {
        "images": np.stack([np.asarray(r.image, dtype=np.uint8) for r in records]),
        "ball": np.stack([np.asarray(r.ball, dtype=float) for r in records]),
        "context_ball": np.stack([np.asarray(r.context_ball, dtype=float) for r in records]),
        "episode": np.array([r.episode for r in records], dtype=np.int64),
    }
