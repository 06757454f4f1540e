"""Named presets: the learner settings of a published campaign, as strategy options.

A preset gives each strategy the options that reproduce a campaign (each strategy's entry in
``explore.learner.strategies.registry.STRATEGIES`` holds them under the preset's name, composed
from the settings below, read by its ``preset_options``; this module imports none of the
strategies); options given on the command line win over it, and a run stores the options it
ran with (``run.json``), so a resumed run needs no preset. Our defaults (the twin's) are
untouched.

``corl2018``: the ArmBalls / Arm-2-Balls campaign of Laversanne-Finot, Péré and Oudeyer (CoRL
2018), from its dataset's config columns (``docs/armballs_published_config.csv``, extracted from
``results/armballs_dataset.pkl`` of github.com/flowersteam/Curiosity_Driven_Goal_Exploration)
and its scripts (``mge_efr.py``, ``mge_representation.py``, ``exploactors.py``,
``interest_model.py``; docs/armballs.md). Each option and why:

- every goal-exploration strategy: ``sigma`` 0.05 (``explo_noise_sdev``, in the [-1, 1]
  parameter units), no random episodes after the bootstrap, ``random_choice`` 0.1
  (``explo_ratio``), the goal cycle of 4 noisy + 1 noise-free episodes per goal
  (``n_explore`` 4; only the exploit updates interest), the exponential interest average with
  ``win_size`` 1000 (the learned runs' and half of the engineered ones'; the other half's
  500 differ by under 0.02 in exploration ratio, docs/armballs.md), competence -min(d, 2);
  the original's inverse model (explauto's ``NonParametric`` with nearest-neighbour models):
  ``one_outcome`` "random" (a module whose recorded outcomes are all one point plays uniform
  parameters, ``bootstrapped_s`` in ``non_parametric.py``) and ``ties`` "spread" (equally near
  episodes are not all answered by the earliest: explauto's kd-tree returns one of them that
  changes as its tree is rebuilt; docs/results_armballs.md, "Stalls: cause and fix");
- engineered (``rge-efr``, ``mge-efr``): 100 bootstrap episodes, goals uniform in the fixed
  box [-1, 1]^d (interest model ``uniform`` over its sensory bounds), the balls' positions as
  features (form ``cartesian``), the distractor's exactly when the rig's scene has one, no hand
  module; RGE-EFR explores (distractor, ball) as one goal (``flat``, representation "flat"),
  MGE-EFR one module per ball (representation "modular");
- learned (``*-vae``, ``*-betavae``, ``rge-online``): 400 bootstrap episodes, goals N(0, 1)
  clipped at 2.5 (interest model ``normal``, ``s_bound`` 2.5), the raw latent means; RGE one
  module of the 10 latents, MGE 5 modules of 2 ranked by KL (the strategies' own modules);
- spatial autoencoder (``*-sae``, not in that campaign): as the learned ones, but its code has
  no prior, so goals uniform in the box [-1, 1]^d, where its image positions lie.

Not reproduced (structure, not settings): the original's context-free database is what a rig
whose scene resets gives (``Scene.resets``); its pre-trained representations are replaced by
ones trained here on the rig's own images (docs/results_armballs.md).
"""

from __future__ import annotations

from typing import Any

CORL2018 = "corl2018"
CORL2018_COMMON: dict[str, Any] = {
    "sigma": 0.05,
    "random_episodes": 0.0,
    "random_choice": 0.1,
    "schedule": "cycle",
    "n_explore": 4,
    "interest": "exponential",
    "window": 1000,
    "competence": "distance",
    "one_outcome": "random",
    "ties": "spread",
}
CORL2018_ENGINEERED: dict[str, Any] = {
    "bootstrap": 100,
    "goals": "box",
    "form": "cartesian",
    "distractor": None,
    "hand_module": False,
}
CORL2018_LEARNED: dict[str, Any] = {"bootstrap": 400, "goals": "normal", "latents": "raw"}
CORL2018_SPATIAL: dict[str, Any] = {"bootstrap": 400, "goals": "box"}

PRESETS = (CORL2018,)
