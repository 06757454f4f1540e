"""Runs: a run's configuration, its folder (``layout``: config, append-only history, metrics),
and the exploration loop that proposes, plays (through the rig's episode player), stores and
learns."""
