"""Runs: a run's configuration, its folder (config, append-only history, metrics), the episode
on a rig, and the exploration loop that proposes, plays, stores and learns."""
