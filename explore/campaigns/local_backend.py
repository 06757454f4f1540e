"""The ``local`` campaign backend: trials in this process (one job) or in spawned worker
processes that die with the campaign."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable

from explore.campaigns.backends import BackendSettings, failure_message, report_line
from explore.campaigns.trial import (
    CampaignError,
    Trial,
    TrialLockedError,
    TrialResult,
    run_trial,
)
from explore.runs.lock import is_being_written

# How often a campaign looks whether another process still writes a trial's run, s (a look
# takes microseconds; a trial takes minutes: a choice).
LOCK_POLL_S = 1.0


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent: int) -> None:
    """Worker initialiser: end this process with SIGTERM when the campaign process that
    started it dies (Linux ``prctl(PR_SET_PDEATHSIG)``), so a campaign killed with SIGKILL
    leaves no worker running its trial on: its run folders are resumed by the next run of the
    command. SIGTERM turns a hardware arm's torque off (``robot.arm``); a twin run just stops
    (its history is crash-safe). Elsewhere than Linux it does nothing."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        return  # not allowed here: the worker runs on as before
    if os.getppid() != parent:  # the parent died before the signal was armed
        os._exit(1)


def run_trial_in_worker(trial: Trial, progress: bool, parent: int) -> TrialResult:
    """``run_trial`` in a pool worker. A SIGTERM inside the trial (the campaign died, see
    ``die_with_parent``) ends it as an exception once torque is off; the pool would then
    report it to nobody and wait for more work forever, so the worker exits instead."""
    try:
        return run_trial(trial, progress)
    finally:
        if os.getppid() != parent:
            os._exit(1)


def run_local(trials: list[Trial], settings: BackendSettings) -> list[TrialResult]:
    """Run trials in this process (jobs 1) or in ``jobs`` spawned processes; a failed trial
    does not stop the others. Raises ``CampaignError`` at the end if any failed."""
    jobs = settings.jobs or 1
    results: list[TrialResult] = []
    failed: list[tuple[Trial, str]] = []
    locked: list[Trial] = []

    def done(trial: Trial, get: Callable[[], TrialResult]) -> None:
        try:
            r = get()
        except TrialLockedError as exc:  # another campaign process runs it: wait, below
            print(f"waiting: {trial.label}: {_one_line(exc)}", file=sys.stderr)
            locked.append(trial)
            return
        except Exception as exc:  # one trial's failure is reported, the others go on
            failed.append((trial, _one_line(exc)))
            return
        results.append(r)
        if settings.progress:
            print(report_line(r), file=sys.stderr)

    if jobs <= 1 or len(trials) <= 1:
        for t in trials:
            done(t, lambda t=t: run_trial(t, settings.progress))
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")  # no inherited GL or torch thread state
        with ProcessPoolExecutor(
            max_workers=jobs, mp_context=ctx, initializer=die_with_parent,
            initargs=(os.getpid(),),
        ) as pool:  # fmt: skip
            futures = [(t, pool.submit(run_trial_in_worker, t, settings.progress, os.getpid()))
                       for t in trials]  # fmt: skip
            for t, f in futures:
                done(t, f.result)
    # Trials another process was writing (two ``ergo experiment`` on one campaign): once it
    # lets go of the run, the trial is run here, which resumes it, or finds it complete (then
    # nothing runs) when the other process finished it.
    while locked:
        trial = locked.pop(0)
        while is_being_written(trial.run_dir):
            time.sleep(LOCK_POLL_S)
        done(trial, lambda t=trial: run_trial(t, settings.progress))
    if failed:
        raise CampaignError(failure_message(failed, len(results)))
    return results
