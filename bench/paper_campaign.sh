#!/usr/bin/env bash
# The paper's experiment on the twin, as docs/results.md reports it: `make paper` (or
# `bash bench/paper_campaign.sh OUT [JOBS]`). Every step is an ordinary ergo command, skipped
# or resumed when it is already done, so the script can be stopped and rerun at any point.
#
# Two conditions, 5000 episodes x exploration seeds 100-107 (never used while developing):
#   stay:       the ball left where it lies (the real rig's way);
#   distractor: the same with a second ball that walks on the ring between episodes.
# Each learned representation is trained on 3000 outcome images of its condition with 8
# training seeds for the spatial autoencoder (4, seeds 4-7, for the distractor's: time), 4 for
# the VAE and the beta-VAE (about 5 CPU
# minutes each on 2 cores beside nothing else); the model a campaign
# uses is the one that best explains held-out images (selection.json), a criterion that never
# looks at the ball's position.
#
# Order: the engineered and spatial-autoencoder comparisons first, then the VAE baselines.
set -euo pipefail
OUT=${1:-runs/paper}
JOBS=${2:-2}
ERGO=${ERGO:-.venv/bin/ergo}
SEEDS=100-107
EPISODES=5000
VAE_RECIPE=(--beta 10 --capacity 10 --capacity-iterations 500 --iterations 700)
BETAVAE_RECIPE=(--beta 4 --capacity 10 --capacity-iterations 500 --iterations 700)
export MUJOCO_GL=${MUJOCO_GL:-egl}
mkdir -p "$OUT"

dataset() {  # dataset FILE SEED [--distractor]
    [ -f "$1" ] || "$ERGO" dataset outcomes --n 3000 --seed "$2" --out "$1" "${@:3}" --no-progress
}
model() {  # model KIND FOLDER DATA SEEDS [recipe...]: trains and selects, unless done
    [ -f "$2/selection.json" ] || "$ERGO" "$1" train --data "$3" --out "$2" --seeds "$4" \
        "${@:5}" --no-progress --device cpu
}
campaign() {  # campaign FOLDER STRATEGIES [options...]
    "$ERGO" experiment --out "$1" --strategies "$2" --seeds "$SEEDS" --episodes "$EPISODES" \
        --jobs "$JOBS" --no-progress "${@:3}"
}

# ---- stay: engineered and spatial autoencoder -------------------------------------------------
dataset "$OUT/data/outcomes.npz" 1000
model sae "$OUT/models/sae" "$OUT/data/outcomes.npz" 0-7
campaign "$OUT/stay" rpe,rge-efr,rge-sae --sae "$OUT/models/sae"

# ---- distractor: engineered and spatial autoencoder, flat and modular -------------------------
WALK=(--rig-option distractor=walk --option rge-efr:distractor=true
      --option mge-efr:distractor=true)
dataset "$OUT/data/outcomes_distractor.npz" 1001 --distractor
model sae "$OUT/models/sae_distractor" "$OUT/data/outcomes_distractor.npz" 4-7
campaign "$OUT/distractor" rpe,rge-efr,mge-efr,rge-sae,mge-sae \
    --sae "$OUT/models/sae_distractor" "${WALK[@]}"

# ---- the paper's VAE baselines ------------------------------------------------------------------
model vae "$OUT/models/vae" "$OUT/data/outcomes.npz" 0-3 "${VAE_RECIPE[@]}"
model vae "$OUT/models/betavae" "$OUT/data/outcomes.npz" 0-3 "${BETAVAE_RECIPE[@]}"
campaign "$OUT/stay" rpe,rge-efr,rge-sae,rge-vae,rge-betavae,mge-vae,rge-online \
    --sae "$OUT/models/sae" --vae "$OUT/models/vae" --betavae "$OUT/models/betavae"
model vae "$OUT/models/betavae_distractor" "$OUT/data/outcomes_distractor.npz" 0-3 \
    "${BETAVAE_RECIPE[@]}"
campaign "$OUT/distractor" rpe,rge-efr,mge-efr,rge-sae,mge-sae,rge-betavae,mge-betavae \
    --sae "$OUT/models/sae_distractor" --betavae "$OUT/models/betavae_distractor" "${WALK[@]}"

# ---- the exploration each training seed's model gives (the representation table) ---------------
for kind in sae vae; do
    for s in $(ls "$OUT/models/$kind" | sed -n 's/^seed-//p'); do
        "$ERGO" experiment --out "$OUT/per_model/$kind-$s" --strategies "rge-$kind" \
            --seeds 100-100 --episodes 1500 --jobs 1 --no-progress --no-report \
            "--$kind" "$OUT/models/$kind/seed-$s" &
        if (( s % JOBS == JOBS - 1 )); then wait; fi
    done
    wait
done
.venv/bin/python bench/representation_table.py "$OUT"
