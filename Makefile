# Two commands for a fresh machine: `make run` and `make test` (see README.md).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# torch 2.13.0 first, from PyTorch's CPU index: its CPU build is what the project is tested
# with; PyPI's torch (a bare `torch` requirement) is the multi-GB CUDA build. A machine that
# cannot reach the index (an offline mirror) finds the wheel through its own pip configuration
# (find-links, extra-index-url); --retries 1 keeps the unreachable index from costing a minute
# of pip's retries (measured offline: 77 s with pip's default 5, 1.4 s with 1).
TORCH_VERSION ?= 2.13.0
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu
EPISODES ?= 300
export MUJOCO_GL ?= egl

.PHONY: run test install lint format bench bench-all paper paper-final clean lerobot-venv test-lerobot

# The LeRobot plugins (lerobot_plugins/, docs/lerobot.md) live in a venv of their own: lerobot
# 0.6.1 needs Python >= 3.12 and torch < 2.12, which from the registry is the CUDA build (about
# 2 GB to download, a 6 GB venv). LEROBOT_PY: the first Python >= 3.12 found (pyenv's versions
# folder first: its shim may not find one); give LEROBOT_PY=/path/to/python3.12 otherwise.
LEROBOT_VERSION ?= 0.6.1
LEROBOT_VENV := .venv-lerobot
LEROBOT_STAMP := $(LEROBOT_VENV)/.installed
LEROBOT_PLUGINS := $(wildcard lerobot_plugins/lerobot_*_ergo_jr)
LEROBOT_PY ?= $(shell for p in $(wildcard $(HOME)/.pyenv/versions/3.1[2-9]*/bin/python3.1[2-9]) \
    python3.12 python3.13 python3; do $$p -c 'import sys; sys.exit(sys.version_info < (3, 12))' \
    2>/dev/null && { echo $$p; break; }; done)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q --retries 1 --index-url $(TORCH_INDEX) torch==$(TORCH_VERSION)
	$(BIN)/pip install -q -e '.[test,ray,export,gym]'
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(BIN)/ergo explore --rig sim --strategy rpe --episodes $(EPISODES) --seed 0 --out runs/demo --resume-or-new

test: $(STAMP)
	$(BIN)/python -m pytest -q
	@if [ -f $(LEROBOT_STAMP) ]; then $(MAKE) --no-print-directory test-lerobot; else echo \
	  "LeRobot plugin tests skipped: no $(LEROBOT_VENV); build it with 'make lerobot-venv'"; fi

# lerobot[dataset,training] first (its torch), then this project and the plugins, editable.
$(LEROBOT_STAMP): pyproject.toml $(addsuffix /pyproject.toml,$(LEROBOT_PLUGINS))
	@test -n "$(LEROBOT_PY)" || { echo "no Python >= 3.12 found: give LEROBOT_PY=/path/to/python3.12"; exit 1; }
	$(LEROBOT_PY) -m venv $(LEROBOT_VENV)
	$(LEROBOT_VENV)/bin/pip install -q --upgrade pip
	$(LEROBOT_VENV)/bin/pip install -q "lerobot[dataset,training]==$(LEROBOT_VERSION)" \
	    "pytest>=8" "pytest-timeout>=2.3"
	$(LEROBOT_VENV)/bin/pip install -q -e '.[export,gym]' $(addprefix -e ,$(LEROBOT_PLUGINS))
	touch $(LEROBOT_STAMP)

lerobot-venv: $(LEROBOT_STAMP)

# The plugins' tests (lerobot_plugins/tests/): the LeRobot user's path, headless.
test-lerobot: $(LEROBOT_STAMP)
	$(LEROBOT_VENV)/bin/python -m pytest -q lerobot_plugins/tests

lint: $(STAMP)
	$(BIN)/ruff format --check . && $(BIN)/ruff check .

format: $(STAMP)
	$(BIN)/ruff format . && $(BIN)/ruff check --fix .

# Benchmarks that need no data: a few minutes each (bench/README.md says what each measures),
# then the twin's touch rate (an experiment: experiments/README.md).
BENCH_QUICK := canopen dynamixel episodes meta_policy rerun
BENCH_VAE := runs/bench-vae

bench: $(STAMP)
	for b in $(BENCH_QUICK); do echo "== bench/bench_$$b.py"; $(BIN)/python bench/bench_$$b.py || exit 1; done
	echo "== experiments/touch_rate.py"; $(BIN)/python experiments/touch_rate.py

# Also Ray against local processes (about 20 min) and the learned goal space: 3000 twin scenes
# rendered into $(BENCH_VAE) (about 5 CPU min), a VAE trained on them (about 10 CPU min), how
# faithful its latents are to the ball (experiments/goal_space.py).
bench-all: bench
	$(BIN)/python bench/bench_ray.py
	$(BIN)/python bench/bench_vae.py --out $(BENCH_VAE) --beta 10 --capacity 10 \
	    --capacity-iterations 500 --iterations 700 --every 100
	$(BIN)/python experiments/goal_space.py --data $(BENCH_VAE)/dataset.npz --vae $(BENCH_VAE)

# The paper's experiment on the twin (docs/results_seeds100.md): datasets, representations
# chosen by a label-free criterion, both conditions x 8 seeds x 5000 episodes. Hours on 2 cores;
# resumable: run it again after anything stopped it.
PAPER ?= runs/paper
paper: $(STAMP)
	bash experiments/paper_campaign.sh $(PAPER) 2

# The final tables on the twin (docs/results.md, results_vae.md, results_distractor.md):
# seeds 700-707, dataset seeds 3000 (and 3001 with the distractor), today's defaults. PAPER_FINAL_PHASES=1: the engineered and
# spatial-autoencoder table alone (about 2 hours on 2 cores); all (the default) adds the VAE
# rows and the distractor condition (several more hours). Resumable.
PAPER_FINAL ?= runs/twin_final
PAPER_FINAL_PHASES ?= all
paper-final: $(STAMP)
	bash experiments/twin_final.sh $(PAPER_FINAL) 2 $(PAPER_FINAL_PHASES)

clean:
	rm -rf $(VENV) $(LEROBOT_VENV) runs .pytest_cache
