#!/bin/sh
# Regenerates the README's pictures of what a researcher sees, from a twin run made with the
# documented commands:
#   docs/img/rerun_view.png       the rerun viewer on the run's recording, default blueprint
#   docs/img/report_coverage.png  `ergo report`'s coverage figure
#   docs/img/report_goals.png     `ergo report`'s goal-space figure
#   docs/img/rerun_lerobot.png    the viewer on a LeRobot dataset exported from a second run
# Needs the project's .venv (`make install`) and a Vulkan or GL adapter for the viewer; no
# display (the viewer runs headless). Without a GPU, Mesa's software rasteriser (lavapipe) does:
#   apt-get install mesa-vulkan-drivers          (Debian/Ubuntu)
# About 2 minutes on 2 shared cores: 300 twin episodes (about 65 s), the report, the viewer.
# The run goes to a temporary folder (kept: its path is printed); RUN=DIR uses DIR instead,
# which must not exist yet.
set -eu
cd "$(dirname "$0")/../.."
BIN=.venv/bin
RUN=${RUN:-$(mktemp -d)/rge-efr-s0}

# the run: goal exploration on the engineered goal space (100 random episodes, then goals)
nice "$BIN/ergo" explore --rig sim --strategy rge-efr --episodes 300 --seed 0 \
    --out "$RUN" --no-progress

# the report figures
nice "$BIN/ergo" report "$RUN" --out "$RUN/report"
cp "$RUN/report/coverage.png" docs/img/report_coverage.png
cp "$RUN/report/goals.png" docs/img/report_goals.png

# the viewer that `ergo replay` opens, on the same files, headless, listening on 127.0.0.1
"$BIN/ergo" replay "$RUN" --print
nice "$BIN/python" docs/img/rerun_screenshot.py --out docs/img/rerun_view.png \
    "$RUN"/recording*.rrd

# a LeRobot dataset: 40 twin episodes with the camera kept at 40 Hz, exported, opened by
# rerun's own LeRobot loader (one recording per episode; episode 5 pushes the ball)
LEROBOT=$(dirname "$RUN")/lerobot
nice "$BIN/ergo" explore --rig sim --strategy rge-efr --strategy-option bootstrap=20 \
    --episodes 40 --seed 0 --out "$LEROBOT/run" --no-progress --rerun off \
    --rig-option record_video=128
nice "$BIN/ergo" export lerobot "$LEROBOT/run" --out "$LEROBOT/dataset"
nice "$BIN/python" docs/img/rerun_screenshot.py --out docs/img/rerun_lerobot.png \
    --timeline frame_index --recording episode_5 --settle 20 "$LEROBOT/dataset"

ls -l docs/img/rerun_view.png docs/img/report_coverage.png docs/img/report_goals.png \
    docs/img/rerun_lerobot.png
echo "run: $RUN"
