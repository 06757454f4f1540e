#!/usr/bin/env bash
# The twin's final table of issue 31 (docs/results.md, "F9"): one command,
# `make paper-final` or `bash experiments/twin_final.sh OUT [JOBS]`. Every step is an ordinary
# ergo command, skipped or resumed when it is already done, so the script can be stopped and
# rerun at any point.
#
# Seeds never used while developing: exploration seeds 700-707 and the outcome dataset's seed
# 3000 (development on the twin used exploration seeds 0-7 and 100-107, the F campaign's, and
# dataset seeds 1000/1001); the spatial autoencoder's training seeds are 700-707 too. The code's
# defaults as they are now, stall_window 10 included (F8): unlike `make paper`, nothing is pinned.
#
# The ball left in place, 5000 episodes x 8 seeds: RGE-EFR and RGE-SAE first (the must-show
# compares them at 1500 and 5000), then RPE. The cells at 1500 are read from the same runs'
# metrics.csv. Then RPE and RGE-EFR of F1 (seed 100) again, to compare. About 7 min of one core
# a run on this machine; the autoencoder's 8 trainings about 25 min on the 2 cores.
#
# Third argument: `vae`, `distractor` or `all` (both) adds phases after phase 1.
# `vae`: the paper's VAE and beta-VAE trained with F6's recipe
# (the decoder over the mean image, the KL term after 1000 iterations and weighed in over 1000
# more, 3000 iterations, training seeds 700-703 each, chosen by held-out explained variance;
# about 9 CPU min a training), then RGE-VAE, RGE-betaVAE, MGE-VAE and RGE-Online x 5000
# episodes on the same seeds (hours). RGE-Online trains its own VAE on its 2000 bootstrap images
# with the same recipe (its options vae_*; about 9 CPU min inside each run).
# `distractor` (issue 31, step 2; F3's condition): the walking red ball, outcome dataset seed
# 3001 with it (never used: development used 1001), the spatial autoencoder trained on it with
# training seeds 700-703, then RGE-EFR, MGE-EFR, RGE-SAE and MGE-SAE x 2000 episodes on seeds
# 700-707, and MGE-EFR without its hand module (F3: hand goals took 38% of its episodes) in a
# campaign of its own. RPE is not run: the distractor changes none of its cells (F3).
set -euo pipefail
OUT=${1:-runs/twin_final}
JOBS=${2:-2}
PHASE=${3:-1}
ERGO=${ERGO:-.venv/bin/ergo}
PY=${PY:-.venv/bin/python}
SEEDS=700-707
EPISODES=5000
HERE=$(cd "$(dirname "$0")" && pwd)
export MUJOCO_GL=${MUJOCO_GL:-egl}
mkdir -p "$OUT/data" "$OUT/models"

DATA="$OUT/data/outcomes-3000.npz"
[ -f "$DATA" ] || "$ERGO" dataset outcomes --n 3000 --seed 3000 --out "$DATA" --no-progress
[ -f "$OUT/models/sae/selection.json" ] || "$ERGO" sae train --data "$DATA" \
    --out "$OUT/models/sae" --seeds "$SEEDS" --device cpu --no-progress

campaign() {  # campaign STRATEGIES: runs or resumes, no report; wall time per call in wall.log
    local t0=$SECONDS
    "$ERGO" experiment --out "$OUT/stay" --episodes "$EPISODES" --strategies "$1" \
        --seeds "$SEEDS" --sae "$OUT/models/sae" --jobs "$JOBS" --no-progress --no-report
    echo "$(date -u +%FT%TZ) $1: $((SECONDS - t0)) s wall" >> "$OUT/wall.log"
}
campaign rge-efr,rge-sae
campaign rpe
"$ERGO" report "$OUT/stay"

# Reruns: the engineered runs of F1 (seed 100, `make paper`'s settings: stall_window off), to
# check that nothing of theirs changed since (F1: RPE 163 cells, RGE-EFR 365 at 5000).
"$ERGO" experiment --out "$OUT/rerun_f1" --episodes "$EPISODES" --strategies rpe,rge-efr \
    --seeds 100-100 --jobs "$JOBS" --option stall_window=0 --no-progress --no-report
if [ "$PHASE" = vae ] || [ "$PHASE" = all ]; then
    AIDS=(--iterations 3000 --lr 1e-3 --lr-final 1e-5 --channels-last --mean-image-offset
          --kl-delay 1000 --kl-warmup 1000)
    [ -f "$OUT/models/vae/selection.json" ] || "$ERGO" vae train --data "$DATA" \
        --out "$OUT/models/vae" --seeds 700-703 --beta 10 --capacity 10 \
        --capacity-iterations 500 "${AIDS[@]}" --device cpu --no-progress
    [ -f "$OUT/models/betavae/selection.json" ] || "$ERGO" vae train --data "$DATA" \
        --out "$OUT/models/betavae" --seeds 700-703 --beta 4 --capacity 10 \
        --capacity-iterations 500 "${AIDS[@]}" --device cpu --no-progress
    "$ERGO" experiment --out "$OUT/stay" --episodes "$EPISODES" \
        --strategies rge-vae,rge-betavae,mge-vae,rge-online --seeds "$SEEDS" \
        --sae "$OUT/models/sae" --vae "$OUT/models/vae" --betavae "$OUT/models/betavae" \
        --option rge-online:vae_iterations=3000 --option rge-online:vae_lr_final=1e-5 \
        --option rge-online:vae_channels_last=true --option rge-online:vae_mean_image_offset=true \
        --option rge-online:vae_kl_delay=1000 --option rge-online:vae_kl_warmup=1000 \
        --jobs "$JOBS" --no-progress --no-report
    "$ERGO" report "$OUT/stay"
fi
if [ "$PHASE" = distractor ] || [ "$PHASE" = all ]; then
    DDATA="$OUT/data/outcomes_distractor-3001.npz"
    [ -f "$DDATA" ] || "$ERGO" dataset outcomes --n 3000 --seed 3001 --out "$DDATA" --distractor \
        --no-progress
    [ -f "$OUT/models/sae_distractor/selection.json" ] || "$ERGO" sae train --data "$DDATA" \
        --out "$OUT/models/sae_distractor" --seeds 700-703 --device cpu --no-progress
    WALK=(--rig-option distractor=walk --seeds "$SEEDS" --episodes 2000 --jobs "$JOBS"
          --no-progress --no-report)
    t0=$SECONDS
    "$ERGO" experiment --out "$OUT/distractor" --strategies rge-efr,mge-efr,rge-sae,mge-sae \
        --sae "$OUT/models/sae_distractor" --option rge-efr:distractor=true \
        --option mge-efr:distractor=true "${WALK[@]}"
    "$ERGO" experiment --out "$OUT/distractor_nohand" --strategies mge-efr \
        --option mge-efr:distractor=true --option mge-efr:hand_module=false "${WALK[@]}"
    echo "$(date -u +%FT%TZ) distractor, 40 runs to 2000: $((SECONDS - t0)) s wall" >> "$OUT/wall.log"
    "$ERGO" report "$OUT/distractor"
    "$ERGO" report "$OUT/distractor_nohand"
fi
"$PY" "$HERE/twin_stalls.py" "$OUT"/stay/rge-efr/seed-* "$OUT"/stay/rge-sae/seed-* \
    > "$OUT/stalls.md"
cat "$OUT/stay/report/summary.md" "$OUT/stalls.md"
