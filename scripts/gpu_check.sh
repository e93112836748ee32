#!/usr/bin/env bash
# The GPU check (docs/cluster.md, "Running on GPUs"): on a machine with the project installed
# (`make install`, or the offline kit: `source .gpu/install.sh`), run the `gpu`-marked tests and
# the race scaling benchmark, then print one summary table. About 10 minutes on an H200, at most
# about 16: every step runs under `timeout`. On a machine without CUDA the tests skip and the
# benchmark runs --quick on the CPU. Steps that cannot run here (no pytest, Ray cannot start)
# print one line and the rest goes on. Usage:  scripts/gpu_check.sh   or   make gpu-check
# Knobs: GPU_CHECK_OUT (default benchmarks/out/gpu_check), GPU_CHECK_TEST_S (240),
# GPU_CHECK_BENCH_S (160; 420 without CUDA), GPU_CHECK_LEARNER_S (60; 120 without CUDA),
# GPU_CHECK_OVERLAP_S (100; 300 without CUDA), GPU_CHECK_ENVS32_S (60; 200 without CUDA),
# GPU_CHECK_SPLIT_S (120; 420 without CUDA), GPU_CHECK_RUNNER_S (60; 120 without CUDA),
# GPU_CHECK_COMPILE_S (120; 200 without CUDA): a limit of 0 skips its step.
# GPU_CHECK_COMPILE_BACKEND: the compiled Learner's dynamo backend (cudagraphs on a GPU: no C
# compiler needed; aot_eager without CUDA; inductor where the node has gcc and Triton).
# GPU_CHECK_RUNNERS (1,14 on a GPU; 1,2 without). GPU_CHECK_TEST_WORKERS (6 on a GPU, where
# pytest-xdist is installed; 0 runs the tests one by one).
set -u
cd "$(dirname "$0")/.."
out=${GPU_CHECK_OUT:-benchmarks/out/gpu_check}
mkdir -p "$out"
rm -rf "$out"/*.xml "$out"/*.log "$out"/learner "$out"/compile "$out"/e2e "$out"/overlap "$out"/envs32 "$out"/split \
  "$out"/runner
if [ -x .venv/bin/python ]; then py=${PYTHON:-.venv/bin/python}; else py=${PYTHON:-python3}; fi
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} RAY_memory_monitor_refresh_ms=0 \
  RAY_DISABLE_DOCKER_CPU_WARNING=1 RAY_USAGE_STATS_ENABLED=0 PYTHONUNBUFFERED=1
if ! "$py" -c "import ray, gymnasium" 2>/dev/null && [ -f .gpu/install.sh ]; then
  echo "gpu-check: ray or gymnasium missing for $py; sourcing the offline kit .gpu/install.sh"
  # shellcheck disable=SC1091
  source .gpu/install.sh
fi
if ! "$py" -c "import torch" 2>/dev/null; then
  echo "gpu-check: $py cannot import torch; install the project first (make install)"; exit 2
fi
cuda=$("$py" -c "import torch; print(int(torch.cuda.is_available()))")
if [ "$cuda" = 1 ]; then
  device=cuda; runners=${GPU_CHECK_RUNNERS:-1,14}; bench_s=160; learner_s=60; overlap_s=100
  envs32_s=60; split_s=120; runner_s=60; test_workers=6; compile_s=120; compile_backend=cudagraphs
else  # a CPU machine checks the script itself: slower, so longer limits
  device=cpu; runners=${GPU_CHECK_RUNNERS:-1,2}; bench_s=420; learner_s=120; overlap_s=300
  envs32_s=200; split_s=420; runner_s=120; test_workers=0; compile_s=200; compile_backend=aot_eager
  echo "gpu-check: torch sees no CUDA device: the gpu tests skip, the benchmark runs on the CPU"
fi
test_s=${GPU_CHECK_TEST_S:-240}; test_workers=${GPU_CHECK_TEST_WORKERS:-$test_workers}; bench_s=${GPU_CHECK_BENCH_S:-$bench_s}
learner_s=${GPU_CHECK_LEARNER_S:-$learner_s}; split_s=${GPU_CHECK_SPLIT_S:-$split_s}
overlap_s=${GPU_CHECK_OVERLAP_S:-$overlap_s}; envs32_s=${GPU_CHECK_ENVS32_S:-$envs32_s}
runner_s=${GPU_CHECK_RUNNER_S:-$runner_s}; compile_s=${GPU_CHECK_COMPILE_S:-$compile_s}
compile_backend=${GPU_CHECK_COMPILE_BACKEND:-$compile_backend}
skip() { [ "$1" = 0 ] && echo "gpu-check: skipped $2 (its limit is 0)"; }
# bench NAME LIMIT WHAT ARGS...: `benchmarks.scaling --quick ARGS` under LIMIT seconds into
# $out/NAME (its scaling.json) and $out/NAME.log; a LIMIT of 0 skips it.
bench() {
  local name=$1 limit=$2 what=$3; shift 3
  skip "$limit" "$what" && return
  echo "gpu-check: $what: benchmarks.scaling --device $device $* (at most $limit s)"
  timeout -k 10 "$limit" "$py" -m benchmarks.scaling --quick --device "$device" "$@" \
    --out "$out/$name" > "$out/$name.log" 2>&1
  echo "gpu-check: benchmark exit $? (log: $out/$name.log)"
}

# 1. The gpu-marked tests: only the files that hold them (collecting the whole suite would
#    import modules whose extras, e.g. highway-env, an offline kit does not carry).
if skip "$test_s" "the gpu tests"; then :
elif "$py" -c "import pytest" 2>/dev/null; then
  files=$(grep -rl --include='*.py' "pytest.mark.gpu" tests | sort)
  # With pytest-xdist the tests run $test_workers at a time: each is a small training run that
  # waits on Ray and RLlib start-ups, not on the GPU, so a 16-core node runs them side by side.
  workers=""
  if [ "$test_workers" != 0 ] && "$py" -c "import xdist" 2>/dev/null; then
    workers="-n $test_workers --dist load"
  fi
  echo "gpu-check: pytest -m gpu on $(echo $files | wc -w) files ${workers:+($workers) }(at most $test_s s)"
  # shellcheck disable=SC2086
  timeout -k 10 "$test_s" "$py" -m pytest -m gpu -q -p no:randomly $workers $files \
    --junitxml="$out/gpu_tests.xml" > "$out/gpu_tests.log" 2>&1
  echo "gpu-check: tests exit $? (log: $out/gpu_tests.log)"
  tail -n 3 "$out/gpu_tests.log"
else
  echo "gpu-check: skipped the gpu tests: pytest is not installed for $py (offline kit: run scripts/gpu_kit_extras.sh before carrying .gpu)" | tee "$out/gpu_tests.log"
fi

# 2. The Learner alone on the most runners' batches at the scale example's minibatch (2,048;
#    at 256 a GPU Learner is the wall: its cost per minibatch hardly depends on the rows).
last=${runners##*,}
bench learner "$learner_s" "Learner alone, $last runners' batches" \
  --runners "$last" --parts learner --minibatch 2048

# 2b. The same with the Learner's whole update compiled (RLlib's torch_compile_learner,
#     complete_update, mode reduce-overhead: on a GPU, CUDA graphs replay the update's ~400
#     kernel launches per minibatch; docs/cluster.md, "Per-minibatch overhead").
bench compile "$compile_s" "Learner alone, compiled ($compile_backend)" --runners "$last" \
  --parts learner --minibatch 2048 --torch-compile reduce-overhead --compile-backend "$compile_backend"

# 3. Sampling and end to end, PPO and PPO+ASOR, fewest and most runners, minibatch 2,048.
bench e2e "$bench_s" "sampling and end to end" --runners "$runners" --parts sample,e2e \
  --minibatch 2048

# 3b. End to end with overlapped sampling (the runners sample batch k+1 while the Learner
#     trains on batch k; rllib_asor/algorithms/ppo/overlap.py) at the most runners.
bench overlap "$overlap_s" "the overlapped end to end" --runners "$last" \
  --algos ppo_overlap,asor_overlap --parts e2e --minibatch 2048

# 3c. Sampling only with 32 envs per runner (the runner's per-call costs, race_net's forward
#     above all, shared by 4× the envs; docs/speed.md), fewest and most runners.
bench envs32 "$envs32_s" "sampling with 32 envs per runner" --runners "$runners" --algos ppo \
  --parts sample --envs-per-runner 32

# 4. Where an iteration's time goes, PPO beside PPO+ASOR (built side by side, iterations
#    interleaved) at the most runners, and the weight sync to that many runners alone.
bench split "$split_s" "the split" --runners "$last" --sync-runners "$last" --parts split,sync \
  --minibatch 2048

# 5. Where one env runner's time goes on this machine (built in this process, no Ray): the
#    physics against race_net's forward, RLlib's connectors and loop, the env's own Python.
if ! skip "$runner_s" "one runner's split"; then
  echo "gpu-check: one runner's split: benchmarks.runner_profile --what split (at most $runner_s s)"
  timeout -k 10 "$runner_s" "$py" -m benchmarks.runner_profile --what split --steps 1024 \
    --out "$out/runner" > "$out/runner.log" 2>&1
  echo "gpu-check: runner split exit $? (log: $out/runner.log)"
fi

# 6. One table.
"$py" -m benchmarks.gpu_check_summary "$out"
