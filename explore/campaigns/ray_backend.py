"""The ``ray`` campaign backend: every trial is a Ray task that writes its run folder.

Joining a cluster (``--ray-address HOST:PORT`` or ``auto``): one host runs ``ray start --head``,
the others ``ray start --address HEAD:PORT``; a host with an arm adds
``--resources '{"rig:ergo1": 1}'`` (``campaign.trial_resources``). The campaign folder must be
on a file system every node mounts at the same path (a worker checks ``campaign.json``'s id).

Without an address, a Ray instance for this campaign alone is started on this machine and shut
down at the end: loopback only, no dashboard, usage statistics off, the smallest object store;
it advertises the campaign's rig, whose arm must then be on this machine. In a process where Ray
is already initialised (a test, a notebook), that connection is used and left open.

A trial is retried after its worker or node died (``BackendSettings.retries``) and resumes
from its run folder; an error raised by the trial itself (a missing calibration, a bad port) is
not retried. The driver first checks that some node advertises every rig the trials need,
and refuses in one line naming the rig otherwise (a Ray task asking for a resource no node has
would wait forever without a word).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import Any

from explore.campaigns.backends import BackendSettings, failure_message, report_line
from explore.campaigns.trial import (
    RIG_RESOURCE_PREFIX,
    CampaignError,
    Trial,
    TrialResult,
    run_trial,
)

RAY_INSTALL = "pip install 'ergo-explore[ray]'"
# Ray 2.60 clusters authenticate with a token by default; a driver joining one by address must
# be told so (measured: without it, "Failed to connect"; docs/campaigns.md).
AUTH_HINT = (
    " (a cluster with token authentication, Ray's default, wants RAY_AUTH_MODE=token on this "
    "host and the head's ~/.ray/auth_token here or in RAY_AUTH_TOKEN)"
)
# CPUs a trial asks Ray for (a scheduling figure; Ray does not pin). Measured here, 60 rpe twin
# episodes in one process: 8.2 s of CPU, 2.0 s in the Python thread (physics, strategy) and
# 6.2 s in Mesa's two llvmpipe threads rendering each episode's images while the Python thread
# waits for them. 1 packs as many trials as cores; that this keeps the cores busier than 2
# would is a guess, not measured.
TRIAL_CPUS = 1.0
# Ray's minimum object store (ray/_private/ray_constants.py OBJECT_STORE_MINIMUM_MEMORY_BYTES,
# 75 MiB); trials return a TrialResult of a few hundred bytes and pass nothing else.
LOCAL_OBJECT_STORE_BYTES = 75 * 1024 * 1024
# How often (s) the driver, while nothing finishes, checks that pending trials' rigs are still
# in the cluster (a guess: a rig trial lasts minutes to hours; one check per 30 s costs nothing).
WAIT_S = 30.0


def import_ray(local: bool) -> Any:
    """Import Ray with usage statistics off; ``local``: keep a Ray instance started by this
    process on 127.0.0.1. Raises ``CampaignError`` with the install command when Ray is absent.
    """
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if local:
        # Ray (2.60, Linux) then takes 127.0.0.1 as the node's address and binds its servers
        # there instead of on every interface (checked with `ss -ltn`, docs/campaigns.md).
        # Read when Ray is imported: it has no effect on a Ray imported earlier.
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    try:
        import ray
    except ImportError:
        raise CampaignError(f"--backend ray needs Ray (an optional extra): {RAY_INSTALL}") from None
    return ray


def connect(ray: Any, settings: BackendSettings, resources: dict[str, float]) -> bool:
    """Connect to Ray; returns True when this call started or joined it (then the caller shuts
    it down). ``resources``: custom resources a local instance advertises."""
    if ray.is_initialized():
        return False
    if settings.ray_address:
        try:
            ray.init(address=settings.ray_address)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            hint = "" if os.environ.get("RAY_AUTH_MODE") else AUTH_HINT
            raise CampaignError(f"--ray-address {settings.ray_address}: {exc}{hint}") from exc
        return True
    ray.init(
        address="local",
        num_cpus=settings.jobs or os.cpu_count() or 1,
        resources=resources,
        include_dashboard=False,
        object_store_memory=LOCAL_OBJECT_STORE_BYTES,
    )
    return True


def check_rig_resources(trials: Iterable[Trial], cluster: dict[str, float]) -> None:
    """Refuse (one line naming the rig) when no node advertises a rig the trials need, or when
    a rig is advertised with a capacity other than 1 (two trials would share one arm).

    ``cluster``: ``ray.cluster_resources()``, resource name -> total over the nodes.
    """
    for name in sorted({r for t in trials for r in t.resources}):
        have = cluster.get(name, 0.0)
        rig_id = name.removeprefix(RIG_RESOURCE_PREFIX)
        if have <= 0:
            raise CampaignError(
                f"no Ray node has rig {rig_id!r}: on the host with that arm run "
                f"ray start --address HEAD:PORT --resources '{{\"{name}\": 1}}'"
            )
        if have != 1:
            raise CampaignError(
                f"the Ray nodes advertise {name} = {have:g} in all: rig {rig_id!r} is one arm "
                "and must be advertised as 1, by its one host (one trial at a time)"
            )


def _trial_task(trial: Trial) -> TrialResult:
    """The Ray task: one trial in a Ray worker (never a progress bar there)."""
    return run_trial(trial, progress=False)


def _why(ray: Any, exc: BaseException) -> str:
    """One line on why a Ray task failed: the trial's own error, or what happened to its
    worker or node."""
    cause = getattr(exc, "cause", None) if isinstance(exc, ray.exceptions.RayTaskError) else None
    text = str(cause if cause is not None else exc).strip() or type(exc).__name__
    return text.splitlines()[0]


def _warn_missing_rigs(ray: Any, trials: Iterable[Trial], warned: set[str]) -> None:
    cluster = ray.cluster_resources()
    for t in trials:
        for name in t.resources:
            if cluster.get(name, 0.0) <= 0 and name not in warned:
                warned.add(name)
                print(f"waiting: {t.label} needs {name} and no Ray node has it now "
                      "(did its host leave the cluster?)", file=sys.stderr)  # fmt: skip


def run_ray(trials: list[Trial], settings: BackendSettings) -> list[TrialResult]:
    """Run the trials as Ray tasks (1 CPU each, plus their rig); raises ``CampaignError`` at the
    end if any failed, the finished ones kept."""
    ray = import_ray(local=settings.ray_address is None)
    needed = {r: 1.0 for t in trials for r in t.resources}
    owned = connect(ray, settings, needed)
    try:
        check_rig_resources(trials, ray.cluster_resources())
        task = ray.remote(_trial_task)
        pending: dict[Any, Trial] = {}
        for t in trials:
            ref = task.options(
                num_cpus=TRIAL_CPUS, resources=t.resources, max_retries=settings.retries,
                retry_exceptions=False, name=f"trial {t.label}",
            ).remote(t)  # fmt: skip
            pending[ref] = t
        results: list[TrialResult] = []
        failed: list[tuple[Trial, str]] = []
        warned: set[str] = set()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
            if not ready:
                _warn_missing_rigs(ray, pending.values(), warned)
                continue
            t = pending.pop(ready[0])
            try:
                r = ray.get(ready[0])
            except ray.exceptions.RayError as exc:
                failed.append((t, _why(ray, exc)))
                continue
            results.append(r)
            if settings.progress:
                print(report_line(r), file=sys.stderr)
        if failed:
            raise CampaignError(failure_message(failed, len(results)))
        return results
    finally:
        if owned:
            ray.shutdown()
