#!/usr/bin/env bash
# Goal selection (option goal_sampling, docs/goal_exploration.md "Choosing goals"): the final
# tables of docs/results_goal_sampling.md, one command,
# `bash experiments/goal_sampling_final.sh OUT [JOBS]`. Every step is an ordinary ergo
# command, skipped or resumed when it is already done, so the script can be stopped and rerun
# at any point (a campaign resumes its unfinished runs; on the twin a resumed run's history
# equals an uninterrupted one's).
#
# Seeds never used while developing the samplers: exploration seeds 800-807, the outcome
# datasets' seed 3100, the spatial autoencoders' training seeds 800-803 (development used
# exploration seeds 0-3). The code's defaults as they are; only goal_sampling changes.
#
# 1. The twin, the ball left in place: RGE-EFR and MGE-EFR with every sampler to 5000
#    episodes (OUT/twin/SAMPLER/STRATEGY/seed-S); RGE-SAE with every sampler to 1500, then to
#    5000 (OUT/twin-sae/SAMPLER/...).
#    The cells at 1500 are read from the same runs' metrics.csv.
# 2. Arm-2-Balls (--preset corl2018), 10,000 episodes: RGE-EFR, RGE-SAE, MGE-EFR, MGE-SAE with
#    uniform, sparse and density (OUT/arm2balls/SAMPLER/...).
# 3. The tables:
#    python experiments/goal_sampling_table.py OUT/twin OUT/twin-sae --at 1500
#    python experiments/goal_sampling_table.py OUT/twin OUT/twin-sae --at 1500,5000
#    python experiments/goal_sampling_table.py OUT/arm2balls --at 5000,9666 --fraction
# Each part's wall time goes to OUT/wall.log.
set -euo pipefail
OUT=${1:-runs/goal_sampling_final}
JOBS=${2:-1}
ERGO=${ERGO:-.venv/bin/ergo}
SEEDS=800-807
SAMPLERS=(uniform density frontier sparse)
export MUJOCO_GL=${MUJOCO_GL:-egl}
export OMP_NUM_THREADS=1  # an autoencoder's training is a function of its seed at a fixed count
mkdir -p "$OUT/data" "$OUT/models"

timed() {  # timed LABEL COMMAND...: run it, its wall time into wall.log
    local label=$1 t0=$SECONDS
    shift
    "$@"
    echo "$label: $((SECONDS - t0)) s wall" >> "$OUT/wall.log"
}

# the twin's outcome dataset and spatial autoencoder
TWIN_DATA="$OUT/data/twin-3100.npz"
[ -f "$TWIN_DATA" ] || "$ERGO" dataset outcomes --n 3000 --seed 3100 --out "$TWIN_DATA" \
    --no-progress
[ -f "$OUT/models/twin-sae/selection.json" ] || timed "twin sae" "$ERGO" sae train \
    --data "$TWIN_DATA" --out "$OUT/models/twin-sae" --seeds 800-803 --device cpu --no-progress
# Arm-2-Balls' outcome dataset and spatial autoencoder
A2B_DATA="$OUT/data/arm2balls-3100.npz"
[ -f "$A2B_DATA" ] || "$ERGO" dataset outcomes --rig arm2balls --n 10000 --seed 3100 \
    --out "$A2B_DATA" --no-progress
[ -f "$OUT/models/a2b-sae/selection.json" ] || timed "arm2balls sae" "$ERGO" sae train \
    --data "$A2B_DATA" --out "$OUT/models/a2b-sae" --seeds 800-803 --device cpu --no-progress

twin() {  # twin FOLDER SAMPLER EPISODES STRATEGIES [FLAGS...]
    local folder=$1 s=$2 n=$3 strategies=$4
    shift 4
    timed "twin $s $strategies $n" "$ERGO" experiment --out "$OUT/$folder/$s" --episodes "$n" \
        --strategies "$strategies" --seeds "$SEEDS" --option "goal_sampling=\"$s\"" \
        --jobs "$JOBS" --no-progress --no-report "$@"
}
for s in "${SAMPLERS[@]}"; do
    twin twin "$s" 5000 rge-efr,mge-efr
    twin twin-sae "$s" 1500 rge-sae --sae "$OUT/models/twin-sae"
done
for s in uniform sparse density frontier; do
    twin twin-sae "$s" 5000 rge-sae --sae "$OUT/models/twin-sae"
done
for s in uniform sparse density; do
    timed "arm2balls $s" "$ERGO" experiment --rig arm2balls --preset corl2018 \
        --out "$OUT/arm2balls/$s" --episodes 10000 --strategies rge-efr,rge-sae,mge-efr,mge-sae \
        --seeds "$SEEDS" --sae "$OUT/models/a2b-sae" --option "goal_sampling=\"$s\"" \
        --jobs "$JOBS" --no-progress --no-report
done
