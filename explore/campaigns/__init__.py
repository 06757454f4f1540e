"""Campaigns: every (strategy, seed) of an experiment a trial that writes one run folder;
planning, the local and Ray backends, and the statistics over seeds."""
