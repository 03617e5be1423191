#!/usr/bin/env bash
# Issue #8 on one GPU: behaviour cloning of the scripted expert on MJX, PPO from the clone, and
# the paired before/after test on 4,096 held-out test seeds. Three stages, each well under 10
# minutes, run from the project root after the install of GPU.md:
#
#   bash benchmarks/ppo_gpu.sh bc      # ~2-3 min: demos on MJX, clone, validation success
#   bash benchmarks/ppo_gpu.sh ppo     # ~6-8 min: PPO, 20M env steps (4,096 envs x 16)
#   bash benchmarks/ppo_gpu.sh test    # ~2 min: both policies on test seeds, exact McNemar
#   bash benchmarks/ppo_gpu.sh scratch # optional, ~6-8 min: the same PPO from a fresh network
#
# Runs live in runs/gpu/ (git-ignored, so kept between calls on a warm machine); each stage
# copies its small outputs (logs, reports, checkpoints, metrics; not the training state) to
# $OUT (default results/ppo_gpu). If the ppo stage is cut off, `bash benchmarks/ppo_gpu.sh
# resume` continues it from its last checkpoint. BACKEND, N_ENVS, N_DEMOS, EVAL_EPISODES,
# TEST_EPISODES and STEPS override the sizes (a CPU smoke test: BACKEND=c and small numbers).
set -euo pipefail
stage=${1:?usage: ppo_gpu.sh bc|ppo|resume|test|scratch}
out=${OUT:-results/ppo_gpu}
runs=runs/gpu
py=${PYTHON:-python3}
steps=${STEPS:-20000000}
backend=${BACKEND:-mjx}
n_envs=${N_ENVS:-4096}
n_demos=${N_DEMOS:-4096}
eval_episodes=${EVAL_EPISODES:-1024}
test_episodes=${TEST_EPISODES:-4096}
mkdir -p "$out" "$runs"
TIMEFORMAT='wall time of the command: %R s'
timed() { local log=$1; shift; { time "$@"; } 2>&1 | tee "$log"; }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader > "$out/gpu.txt" || true

case $stage in
  bc)
    timed "$out/bc.log" "$py" -m openral_mjx.finetune bc --backend "$backend" \
      --n-demos "$n_demos" --n-envs "$n_envs" --eval-episodes "$eval_episodes" --out "$runs/bc"
    rm -rf "$out/bc" && cp -r "$runs/bc" "$out/"
    ;;
  ppo | resume)
    [ -d "$runs/bc" ] || { echo "no $runs/bc: run the bc stage first (the machine went cold?)"; exit 1; }
    if [ "$stage" = ppo ]; then
      args=(--backend "$backend" --init "$runs/bc" --n-envs "$n_envs" --unroll-length 16
            --minibatches 8 --eval-every 25 --checkpoint-every 50
            --eval-episodes "$eval_episodes" --eval-n-envs "$eval_episodes")
    else
      args=(--resume)
    fi
    timed "$out/$stage.log" "$py" -m openral_mjx.finetune ppo --out "$runs/ppo" \
      --num-timesteps "$steps" "${args[@]}"
    rm -rf "$out/ppo" && mkdir -p "$out/ppo"
    cp -r "$runs/ppo/run.json" "$runs/ppo/metrics.jsonl" "$runs/ppo/best" "$runs/ppo/final" "$out/ppo/"
    cp "$runs/ppo/learning_curve.png" "$out/ppo/" 2>/dev/null || true
    ;;
  scratch)
    timed "$out/scratch.log" "$py" -m openral_mjx.finetune ppo --out "$runs/scratch" \
      --num-timesteps "$steps" --backend "$backend" --n-envs "$n_envs" --unroll-length 16 \
      --minibatches 8 --eval-every 25 --checkpoint-every 50 \
      --eval-episodes "$eval_episodes" --eval-n-envs "$eval_episodes"
    rm -rf "$out/scratch" && mkdir -p "$out/scratch"
    cp -r "$runs/scratch/run.json" "$runs/scratch/metrics.jsonl" "$runs/scratch/best" "$out/scratch/"
    ;;
  test)
    for name in bc ppo/best; do
      tag=${name%%/*}
      timed "$out/test_$tag.log" "$py" -m openral_mjx.eval --backend "$backend" \
        --policy "mlp:$runs/$name" --seed 2000000000 --n-episodes "$test_episodes" \
        --n-envs "$n_envs" --out "$out/test_$tag.json"
    done
    "$py" -m openral_mjx.compare "$out/test_bc.json" "$out/test_ppo.json" --confidence 0.99 \
      | tee "$out/paired.log"
    ;;
  *) echo "unknown stage $stage: bc, ppo, resume, test or scratch"; exit 2 ;;
esac
