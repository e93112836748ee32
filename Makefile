# The README's two commands: `make train` and `make test`. Both create .venv if missing.
SHELL       := /bin/bash
.SHELLFLAGS := -o pipefail -c
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# Ray on a small machine: no dashboard, no memory monitor kills mid-test.
export RAY_memory_monitor_refresh_ms := 0
export RAY_DISABLE_DOCKER_CPU_WARNING := 1
export MUJOCO_GL ?= egl
# This machine's pip config lists package indexes that do not exist here: pip warns once per
# package ("Location ... is ignored"). Not ours to print; every other pip line is kept.
comma := ,
PIP_FILTER := 2>&1 | { grep -v "^WARNING: Location '.*' is ignored" || true; }

.PHONY: install train smoke test test-slow lint bench clean docs compat

# $(call venv_install,VENV,EXTRAS,MORE): VENV (created if missing) gets pip, torch and this tree
# installed editable with EXTRAS, plus the requirements MORE (in the same resolve).
define venv_install
	test -x $(1)/bin/python || $(PYTHON) -m venv $(1)
	$(1)/bin/python -m pip install -q --upgrade pip setuptools wheel $(PIP_FILTER)
	# torch pinned to the CPU build (a local wheel here); never an open `torch` requirement.
	$(1)/bin/python -m pip install -q "torch==2.13.0" $(PIP_FILTER)
	# compat: a plain .pth to the source tree. With setuptools 84 and pip 26 every editable mode
	# prints a banner (compat: "transitional"; lenient, strict: a notice); this one message is
	# hidden by a Python warning filter, which pip passes on to the build backend.
	PYTHONWARNINGS="ignore:Compat editable installs" \
	  $(1)/bin/python -m pip install -q -e ".[$(2)]" $(3) --config-settings editable_mode=compat \
	  $(PIP_FILTER)
endef

$(STAMP): pyproject.toml
	$(call venv_install,$(VENV),test$(comma)docs,)
	touch $(STAMP)

# The paper's sweep files read demonstrations that make.py writes (seconds; not kept in git).
DEMOS_DIR := tuned_examples/paper/demonstrations
DEMOS     := $(addprefix $(DEMOS_DIR)/,lava-expert.npz walker2d-gravity-random.npz \
               halfcheetah-damping-random.npz)
$(DEMOS) &: $(STAMP) $(DEMOS_DIR)/make.py
	$(PY) $(DEMOS_DIR)/make.py

install: $(STAMP) $(DEMOS)

# The main job: train a racer (~5 min on 2 idle cores), evaluate it on unseen courses, report + GIF.
train: $(STAMP)
	$(VENV)/bin/rllib quickstart

# The 1-minute smoke run of the same pipeline (learns nothing).
smoke: $(STAMP)
	$(VENV)/bin/rllib quickstart --test

# Two pytest workers (pytest-xdist): on 2 cores most tests wait on Ray and RLlib start-ups, so two
# at once finish the suite in about two thirds of the time. TEST_WORKERS=0 runs them one by one.
TEST_WORKERS ?= 2
test: $(STAMP) $(DEMOS)
	$(PY) -m pytest -q --timeout=900 --durations=30 -n $(TEST_WORKERS) --dist worksteal

# The `slow` tests: long end-to-end runs, and runs whose behaviour a faster test in `make test`
# covers (each names it). About half an hour on 2 cores.
test-slow: $(STAMP) $(DEMOS)
	$(PY) -m pytest -q -m slow --timeout=1800 --durations=20 -n $(TEST_WORKERS) --dist worksteal

lint: $(STAMP)
	$(VENV)/bin/ruff check rllib_asor game_env tests benchmarks studies mkdocs_hooks.py

# The documentation site with the API reference (mkdocs.yml) in site/: any warning, a broken
# link or a docstring that does not parse, fails it (tests/test_docs_build.py runs the same).
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict -d site

# Offline datasets (docs/offline.md): per env and dynamics a PPO (or SAC) run, then random /
# medium / expert / medium-replay data in data/offline/<task>/. Scale with the variables.
DATASET_ENVS  ?= rllib_asor/HopperShift-v0
DATASET_STEPS ?= 10000
TRAINER       ?= ppo
TRAIN_STEPS   ?= 200000
.PHONY: datasets
datasets: $(STAMP)
	for env in $(DATASET_ENVS); do \
	  nice $(VENV)/bin/rllib data collect --env $$env --out data/offline \
	    --steps $(DATASET_STEPS) --trainer $(TRAINER) --train-steps $(TRAIN_STEPS) --overwrite || exit 1; \
	done

bench: $(STAMP)
	$(PY) -m benchmarks.run_all

# The GPU check (docs/cluster.md): the gpu-marked tests and the race scaling benchmark, one
# table, at most ~8 min. Uses .venv if there is one, else python3 (the offline GPU kit).
.PHONY: gpu-check
gpu-check:
	scripts/gpu_check.sh

# Each study's page, docs/studies/<name>.md, generated from its run files (studies/lib/pages.py).
.PHONY: results
results: $(STAMP)
	$(PY) -m studies.lib.pages

# Mutation testing (docs/testing.md; not part of `make test`): one mutmut run per package of
# benchmarks/mutation/packages.toml, under nice, in build/mutation/<package>/. Long on 2 cores:
# pick packages with MUTATION_PACKAGES="asor legacy"; MUTATION_ARGS="--rerun-open" retests only
# the last run's survivors and timeouts (after new tests), "--report" only prints the kill ratios.
MUTMUT_VERSION      ?= 3.8.1
MUTATION_PACKAGES   ?=
MUTATION_ARGS       ?= --check
.PHONY: mutation
mutation: $(STAMP)
	$(PY) -c "import mutmut" 2>/dev/null || \
	  $(PY) -m pip install -q "mutmut==$(MUTMUT_VERSION)" $(PIP_FILTER)
	$(PY) -m benchmarks.mutation.run $(MUTATION_ARGS) $(MUTATION_PACKAGES)

# The compat and glue tests on another Ray release of the supported range (pyproject.toml,
# rllib_asor/ray_compat.py): `make compat RAY=2.58.1`. Its own venv, .venv-ray-<release> (built
# once, reused; `make clean` removes it), holds torch, that Ray and this tree (editable).
RAY_RELEASES := 2.58.0 2.58.1 2.59.0 2.60.0
COMPAT_TESTS := tests/rllib tests/algorithms/test_fast_sac.py tests/algorithms/escp \
                tests/cli/test_e2e.py
ifneq ($(filter compat,$(MAKECMDGOALS)),)
ifneq ($(filter-out $(RAY_RELEASES),$(RAY))$(words $(RAY)),1)
$(error make compat: RAY='$(RAY)' is not a tested Ray release; allowed: one of $(RAY_RELEASES), e.g. make compat RAY=$(lastword $(RAY_RELEASES)))
endif
endif
.PHONY: compat
compat: .venv-ray-$(RAY)/.installed
	.venv-ray-$(RAY)/bin/python -m pytest -q --timeout=900 --durations=10 -n $(TEST_WORKERS) \
	  $(COMPAT_TESTS)

.venv-ray-%/.installed: pyproject.toml
	$(call venv_install,.venv-ray-$*,test,"ray[rllib$(comma)tune]==$*")
	.venv-ray-$*/bin/python -c "import ray; assert ray.__version__ == '$*', ray.__version__"
	touch $@

clean:
	rm -rf $(VENV) .venv-ray-* *.egg-info
