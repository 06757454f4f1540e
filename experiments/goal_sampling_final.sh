#!/usr/bin/env bash
# Goal selection (option goal_sampling, docs/goal_exploration.md "Choosing goals"): the final
# tables, one command, `bash experiments/goal_sampling_final.sh OUT [JOBS] [SAMPLERS]`. Every
# step is an ordinary ergo command, skipped or resumed when it is already done, so the script
# can be stopped and rerun at any point (a campaign resumes its unfinished runs).
#
# Seeds never used while developing the samplers: exploration seeds 800-807, the outcome
# datasets' seed 3100, the spatial autoencoders' training seeds 800-803 (development used
# exploration seeds 0-3). The code's defaults as they are now; only goal_sampling changes.
#
# 1. The twin, the ball left in place, 5000 episodes x 8 seeds: RGE-EFR, RGE-SAE and MGE-EFR,
#    one campaign folder per sampler (OUT/twin/SAMPLER/STRATEGY/seed-S); the cells at 1500 are
#    read from the same runs' metrics.csv. Compare with
#    `python experiments/goal_sampling_table.py OUT/twin --at 1500,5000`.
# 2. Arm-2-Balls (--preset corl2018), 10,000 episodes x 8 seeds: RGE-EFR, RGE-SAE, MGE-EFR,
#    MGE-SAE, one campaign folder per sampler (OUT/arm2balls/SAMPLER/...).
#
# SAMPLERS: comma-separated, default uniform,density,frontier,sparse. Each campaign's wall time
# goes to OUT/wall.log.
set -euo pipefail
OUT=${1:-runs/goal_sampling_final}
JOBS=${2:-2}
SAMPLERS=${3:-uniform,density,frontier,sparse}
ERGO=${ERGO:-.venv/bin/ergo}
SEEDS=800-807
export MUJOCO_GL=${MUJOCO_GL:-egl}
export OMP_NUM_THREADS=1  # an autoencoder's training is a function of its seed at a fixed count
mkdir -p "$OUT/data" "$OUT/models"

# the twin's outcome dataset and spatial autoencoder
TWIN_DATA="$OUT/data/twin-3100.npz"
[ -f "$TWIN_DATA" ] || "$ERGO" dataset outcomes --n 3000 --seed 3100 --out "$TWIN_DATA" \
    --no-progress
[ -f "$OUT/models/twin-sae/selection.json" ] || "$ERGO" sae train --data "$TWIN_DATA" \
    --out "$OUT/models/twin-sae" --seeds 800-803 --device cpu --no-progress
# Arm-2-Balls' outcome dataset and spatial autoencoder
A2B_DATA="$OUT/data/arm2balls-3100.npz"
[ -f "$A2B_DATA" ] || "$ERGO" dataset outcomes --rig arm2balls --n 10000 --seed 3100 \
    --out "$A2B_DATA" --no-progress
[ -f "$OUT/models/a2b-sae/selection.json" ] || "$ERGO" sae train --data "$A2B_DATA" \
    --out "$OUT/models/a2b-sae" --seeds 800-803 --device cpu --no-progress

timed() {  # timed LABEL COMMAND...: run it, its wall time into wall.log
    local label=$1 t0=$SECONDS
    shift
    "$@"
    echo "$(date -u +%FT%TZ) $label: $((SECONDS - t0)) s wall" >> "$OUT/wall.log"
}

IFS=, read -r -a samplers <<< "$SAMPLERS"
for s in "${samplers[@]}"; do
    timed "twin $s" "$ERGO" experiment --out "$OUT/twin/$s" --episodes 5000 \
        --strategies rge-efr,rge-sae,mge-efr --seeds "$SEEDS" --sae "$OUT/models/twin-sae" \
        --option "goal_sampling=\"$s\"" --jobs "$JOBS" --no-progress --no-report
done
for s in "${samplers[@]}"; do
    timed "arm2balls $s" "$ERGO" experiment --rig arm2balls --preset corl2018 \
        --out "$OUT/arm2balls/$s" --episodes 10000 --strategies rge-efr,rge-sae,mge-efr,mge-sae \
        --seeds "$SEEDS" --sae "$OUT/models/a2b-sae" --option "goal_sampling=\"$s\"" \
        --jobs "$JOBS" --no-progress --no-report
done
for s in "${samplers[@]}"; do
    "$ERGO" report "$OUT/twin/$s" > /dev/null
    "$ERGO" report "$OUT/arm2balls/$s" > /dev/null
done
