"""Campaign backends: how trials run, from a table of name -> "module:function" imported lazily
(as the rigs are): ``local`` (this machine's processes, no Ray; explore/campaigns/local_backend.py)
and ``ray`` (Ray tasks on a cluster, explore/campaigns/ray_backend.py); and what both print.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from explore.campaigns.trial import CampaignError, Trial, TrialResult
from plumbing.registry import LazyTable

# backend name -> "module:function(trials, settings) -> list[TrialResult]", imported lazily so
# that the local backend never imports Ray
BACKENDS = LazyTable(
    "campaign backend",
    {
        "local": "explore.campaigns.local_backend:run_local",
        "ray": "explore.campaigns.ray_backend:run_ray",
    },
    error=CampaignError,
)


# Restarts of a trial whose worker or node died (a guess: enough for a node lost once or a
# worker killed by an OOM spike, few enough that a trial that kills its worker every time
# does not hold a rig for long).
DEFAULT_RETRIES = 2


@dataclass(frozen=True)
class BackendSettings:
    """How a backend runs trials.

    Attributes:
        jobs: local: processes at once; ray: CPUs of a Ray instance started for this campaign
            (ignored when joining a cluster, whose CPUs decide). None = the backend's default.
        progress: progress bars (local) or one line per finished trial (both), on stderr.
        ray_address: ray: the cluster to join (``HOST:PORT`` or ``auto``); None = start a
            local Ray instance on 127.0.0.1 for the campaign.
        retries: ray: times a trial is restarted after its worker or node died (it resumes
            from its run folder); errors raised by the trial itself are never retried.
    """

    jobs: int | None = None
    progress: bool = False
    ray_address: str | None = None
    retries: int = DEFAULT_RETRIES


def load_backend(name: str) -> Callable[[list[Trial], BackendSettings], list[TrialResult]]:
    """The backend's ``run(trials, settings)`` (``CampaignError`` for an unknown one)."""
    return BACKENDS.load(name)


def report_line(r: TrialResult) -> str:
    """One line on a finished trial (progress output)."""
    resumed = f", resumed at {r.resumed_from}" if r.resumed_from else ""
    if r.resumed_from >= r.episodes:
        resumed = ", complete already (an earlier or another campaign process ran it)"
    return (f"done: {r.strategy} seed {r.seed}: {r.episodes} episodes, {r.cells} ball cells "
            f"({r.host} pid {r.pid}, {r.wall_s:.1f} s{resumed})")  # fmt: skip


def failure_message(failed: list[tuple[Trial, str]], finished: int) -> str:
    """The one-line error of a campaign some of whose trials failed."""
    first, why = failed[0]
    more = f" and {len(failed) - 1} more" if len(failed) > 1 else ""
    return (f"{len(failed)} trial(s) failed ({first.label}: {why}{more}); {finished} finished "
            "and are kept; rerun the same command to resume the others")  # fmt: skip
