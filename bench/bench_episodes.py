"""Twin episodes per second per worker, against the bound measured in the same run.

For each strategy (rpe, rge-efr, rge-vae) and each render setting (the scene's chosen one and,
with ``--mujoco-defaults``, MuJoCo's default visual quality, the peer the chosen settings are
measured against: what the twin rendered with before 2026-12-01), episodes run
through the whole loop (``Explorer.step``: DMP at 40 Hz through the Arm's safety clamp, settle,
outcome render, store, strategy update, metrics). The bound of an episode is its own physics
(the same actuator targets and steps, replayed from the same state on a second twin, MuJoCo
called directly) plus one outcome render at the run's own render settings, with nothing else.

Rounds: a block of episodes, then the bound of the same block, so both see the same machine
load; each round gives one ratio (episode cost / bound), in wall time and in the process's CPU
time. This host swings a one-shot ratio from 0.7 to 2.7 when idle, so the figure is the median
of the rounds' ratios with their spread (the lowest and highest round, and the quartiles).
Targets: >= 40 rge-efr episodes/s on an idle core, episode cost <= 1.15x the bound.

    .venv/bin/python bench/bench_episodes.py [--episodes 300] [--block 20] [--mujoco-defaults]
        [--vae MODEL]   # rge-vae's model (default: an untrained VAE of the paper's
                        # architecture: encoding costs the same)
        [--phases]      # also where an episode's time goes beyond its physics, per phase

``--phases``: one more run of each strategy (no bound), each phase of ``Explorer.step`` timed
around its call (the phases of ``EpisodeRunner`` and the store, strategy, metrics and
fingerprint calls), the physics steps inside a phase subtracted (MuJoCo's ``mj_step`` timed on
its own): milliseconds an episode, wall. The timers cost about 1 us a call.

rge-vae's first ``bootstrap`` (100) episodes are random, as in a run; the figure covers both.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from explore.rigs.rig import make_rig
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.open_run import open_run
from sim.camera import SimCamera
from sim.twin import Twin

STRATEGIES = ("rpe", "rge-efr", "rge-vae")
# MuJoCo's default visual quality (MJCF reference, <visual><quality>) and the scene's floor grid
# before it set its own (sim/models/make_scene.py): the peer of the chosen render settings.
MUJOCO_SHADOW_SIZE = 4096  # px
MUJOCO_OFFSAMPLES = 4
OLD_FLOOR_GRID = 0.01  # m (shadows show it)
QUALITIES = ("chosen", "mujoco")


def use_mujoco_defaults(twin: Twin) -> None:
    """Render ``twin`` with MuJoCo's default quality: a 4096 px shadow map, 4x multisampling,
    every light casting shadows, the floor on a 1 cm grid (physics unchanged)."""
    quality = twin.model.vis.quality
    quality.shadowsize, quality.offsamples = MUJOCO_SHADOW_SIZE, MUJOCO_OFFSAMPLES
    twin.model.light_castshadow[:] = 1
    twin.model.geom_size[twin.model.geom("floor").id, 2] = OLD_FLOOR_GRID


def untrained_vae(folder: Path) -> Path:
    """An untrained VAE of the paper's architecture, saved in ``folder`` (timing only)."""
    import torch

    from vision.vae import Vae, limit_threads

    limit_threads()
    torch.manual_seed(0)
    return Vae().save(folder)


def bound_frame(camera: SimCamera, obs: int) -> None:
    """One outcome image exactly as the sim rig makes it."""
    camera.read_square(obs)


class ControlTrace:
    """Records what the episode asked of the physics: (actuator targets (6,) rad, number of
    physics steps) in order, by wrapping the twin's ``set_targets`` and ``step`` (a dict
    append a call: noise against a 30 ms episode)."""

    def __init__(self, twin: Twin) -> None:
        self.twin = twin
        self.calls: list[tuple[np.ndarray, int]] = []
        set_targets, step = twin.set_targets, twin.step

        def traced_set_targets(q: np.ndarray) -> None:
            set_targets(q)
            self._targets = twin.data.ctrl.copy()

        def traced_step(seconds: float | None = None) -> None:
            n = 1 if seconds is None else max(1, round(seconds / twin.timestep))
            self.calls.append((self._targets, n))
            step(seconds)

        self._targets = twin.data.ctrl.copy()
        twin.set_targets = traced_set_targets  # type: ignore[method-assign]
        twin.step = traced_step  # type: ignore[method-assign]

    def take(self) -> list[tuple[np.ndarray, int]]:
        calls, self.calls = self.calls, []
        return calls


@dataclass
class Rounds:
    """Per round: seconds of the block's episodes and of their bound, wall and CPU (of this
    process), and the physics steps of the block."""

    run_s: list[float] = field(default_factory=list)
    bound_s: list[float] = field(default_factory=list)
    run_cpu: list[float] = field(default_factory=list)
    bound_cpu: list[float] = field(default_factory=list)
    episodes: list[int] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)

    def ratios(self, cpu: bool) -> np.ndarray:
        """Each round's episode cost over its bound."""
        run, bound = (self.run_cpu, self.bound_cpu) if cpu else (self.run_s, self.bound_s)
        return np.array(run) / np.array(bound)

    def rate(self, cpu: bool, bound: bool) -> float:
        """Episodes per second over all rounds."""
        s = (self.bound_cpu if cpu else self.bound_s) if bound else (
            self.run_cpu if cpu else self.run_s)  # fmt: skip
        return sum(self.episodes) / sum(s)


def measure(strategy: str, quality: str, episodes: int, block: int, vae: Path) -> Rounds:
    """Run ``episodes`` episodes in rounds of ``block``: each round the block's episodes
    through the whole loop, then their bound.

    The bound replays each episode's own physics on a second twin started from the same state
    (same actuator targets, same steps: the same contacts and solver work), with MuJoCo called
    directly, plus one outcome image."""
    options = {"vae": str(vae)} if strategy == "rge-vae" else {}
    config = RunConfig(
        strategy=StrategyConfig(strategy, options),
        episodes=episodes,
    )
    rig = make_rig(config.rig)
    twin = rig.sensor.twin
    bound_twin = Twin(render_size=twin.render_size)
    if quality == "mujoco":
        use_mujoco_defaults(twin)
        use_mujoco_defaults(bound_twin)
    bound_camera = SimCamera(bound_twin)
    out = Rounds()
    with tempfile.TemporaryDirectory() as tmp, rig, bound_camera:
        run = open_run(Path(tmp) / "run", config, mode="new", rig=rig)
        explorer = run.explorer()
        obs = explorer.runner.config.obs_size
        explorer.runner.observe(render=True)  # warm both renderers up outside the timings
        bound_frame(bound_camera, obs)
        trace = ControlTrace(twin)
        model, data = bound_twin.model, bound_twin.data
        for first in range(0, episodes, block):
            replays = []
            run_s = run_cpu = bound_s = bound_cpu = 0.0
            for k in range(first, min(first + block, episodes)):
                start = twin.get_state()
                t0, c0 = time.perf_counter(), time.process_time()
                explorer.step(k)
                run_s += time.perf_counter() - t0
                run_cpu += time.process_time() - c0
                replays.append((start, trace.take()))
            for start, calls in replays:
                bound_twin.set_state(start)
                t0, c0 = time.perf_counter(), time.process_time()
                for q, n in calls:
                    data.ctrl[:] = q
                    mujoco.mj_step(model, data, nstep=n)
                bound_frame(bound_camera, obs)
                bound_s += time.perf_counter() - t0
                bound_cpu += time.process_time() - c0
            out.run_s.append(run_s)
            out.run_cpu.append(run_cpu)
            out.bound_s.append(bound_s)
            out.bound_cpu.append(bound_cpu)
            out.episodes.append(len(replays))
            out.steps.append(sum(n for _, calls in replays for _, n in calls))
        run.close()
    bound_twin.close()
    return out


class PhaseTimer:
    """Wall time of named calls, less the physics steps made inside them (``mj_step``, timed
    apart through a proxy of ``sim.twin``'s ``mujoco``)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._open: list[list[float]] = []  # per open call: the physics inside it, s

    def physics(self) -> object:
        """A stand-in for the ``mujoco`` module whose ``mj_step`` is timed as "physics"."""
        timer, step = self, mujoco.mj_step

        class Mujoco:
            def __getattr__(self, name: str) -> object:
                return getattr(mujoco, name)

            @staticmethod
            def mj_step(model: object, data: object, nstep: int = 1) -> None:
                t = time.perf_counter()
                step(model, data, nstep=nstep)
                dt = time.perf_counter() - t
                timer.seconds["physics (mj_step)"] = timer.seconds.get("physics (mj_step)", 0) + dt
                for inside in timer._open:
                    inside[0] += dt

        return Mujoco()

    def wrap(self, obj: object, method: str) -> None:
        """Time ``obj.method`` as "Class.method" (nested calls count in both)."""
        call, label = getattr(obj, method), f"{type(obj).__name__}.{method}"

        def timed(*args: object, **kwargs: object) -> object:
            inside = [0.0]
            self._open.append(inside)
            t = time.perf_counter()
            try:
                return call(*args, **kwargs)
            finally:
                self._open.pop()  # calls nest: the innermost is the last
                spent = time.perf_counter() - t - inside[0]
                self.seconds[label] = self.seconds.get(label, 0.0) + spent

        setattr(obj, method, timed)


def phases(strategy: str, episodes: int, vae: Path) -> tuple[dict[str, float], float]:
    """Milliseconds an episode per phase (physics apart) and in all, over ``episodes``
    episodes after 20 unmeasured ones."""
    import sim.twin

    timer = PhaseTimer()
    options = {"vae": str(vae)} if strategy == "rge-vae" else {}
    config = RunConfig(strategy=StrategyConfig(strategy, options), episodes=episodes + 20)
    rig = make_rig(config.rig)
    real_mujoco = sim.twin.mujoco
    sim.twin.mujoco = timer.physics()  # type: ignore[assignment]
    try:
        with tempfile.TemporaryDirectory() as tmp, rig:
            run = open_run(Path(tmp) / "run", config, mode="new", rig=rig)
            explorer = run.explorer()
            runner = explorer.runner
            for obj, names in [
                (runner, ("go_rest", "play", "settle", "observe")),
                (explorer.store, ("append",)),
                (explorer.strategy, ("propose", "update")),
                (explorer.metrics, ("update", "append_last")),
                (explorer.fingerprint, ("add",)),
            ]:
                for name in names:
                    timer.wrap(obj, name)
            for k in range(20):
                explorer.step(k)
            timer.seconds.clear()
            t = time.perf_counter()
            for k in range(20, episodes + 20):
                explorer.step(k)
            total = time.perf_counter() - t
            run.close()
    finally:
        sim.twin.mujoco = real_mujoco
    per = {k: 1e3 * v / episodes for k, v in timer.seconds.items()}
    return per, 1e3 * total / episodes


def spread(ratios: np.ndarray) -> str:
    """``median [low, q1-q3, high]`` of the rounds' ratios."""
    q1, med, q3 = np.percentile(ratios, [25, 50, 75])
    return f"{med:5.2f} [{ratios.min():.2f}, {q1:.2f}-{q3:.2f}, {ratios.max():.2f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=300)
    ap.add_argument("--block", type=int, default=20, help="episodes a round")
    ap.add_argument(
        "--mujoco-defaults", action="store_true", help="also MuJoCo's default render quality"
    )
    ap.add_argument("--strategies", default=",".join(STRATEGIES))
    ap.add_argument("--vae", type=Path, default=None, help="rge-vae's model (default: untrained)")
    ap.add_argument("--phases", action="store_true", help="also each phase's time an episode")
    args = ap.parse_args()

    qualities = QUALITIES if args.mujoco_defaults else QUALITIES[:1]
    with tempfile.TemporaryDirectory() as tmp:
        vae = args.vae or untrained_vae(Path(tmp) / "vae")
        print("cost/bound: the median of the rounds' ratios [lowest, quartiles, highest]")
        print(f"{'strategy':10s} {'render':8s} {'rounds':>6s} {'episodes/s':>10s} "
              f"{'bound/s':>8s} {'cost/bound, wall':>32s} {'cost/bound, CPU':>32s} "
              f"{'steps':>6s}")  # fmt: skip
        rates: dict[tuple[str, str], float] = {}
        for strategy in args.strategies.split(","):
            for quality in qualities:
                r = measure(strategy, quality, args.episodes, args.block, vae)
                rates[strategy, quality] = rate = r.rate(cpu=False, bound=False)
                print(
                    f"{strategy:10s} {quality:8s} {len(r.episodes):6d} {rate:10.1f} "
                    f"{r.rate(cpu=False, bound=True):8.1f} {spread(r.ratios(False)):>32s} "
                    f"{spread(r.ratios(True)):>32s} {sum(r.steps) / sum(r.episodes):6.0f}",
                    flush=True,
                )
        if args.phases:
            for strategy in args.strategies.split(","):
                per, total = phases(strategy, args.episodes, vae)
                listed = sum(per.values())
                print(
                    f"{strategy}: {total:.2f} ms an episode, wall; each phase beyond its physics:"
                )
                for name, ms in sorted(per.items(), key=lambda kv: -kv[1]):
                    print(f"  {name:28s} {ms:6.3f} ms")
                print(f"  {'the rest of Explorer.step':28s} {total - listed:6.3f} ms")
    if args.mujoco_defaults:
        for strategy in args.strategies.split(","):
            gain = rates[strategy, "chosen"] / rates[strategy, "mujoco"]
            print(f"{strategy}: chosen render {gain:.1f}x the episodes/s of MuJoCo's defaults")
    print("targets: rge-efr >= 40 episodes/s on an idle core; cost/bound <= 1.15")


if __name__ == "__main__":
    main()
