"""The learner and the experiments, in wings, each one kind of thing (docs/architecture.md):
``learner`` (motor primitives, goal spaces, meta-policy, strategies), ``rigs`` (a rig = an arm,
a camera and a clock, built by name), ``runs`` (a run's config, folder, episodes and loop),
``campaigns`` (many runs, locally or on Ray), ``report`` (figures, summaries, the rerun
recording) and ``cli`` (the ``ergo`` command)."""
