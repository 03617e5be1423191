#!/usr/bin/env bash
# The GPU measurements behind BENCHMARKS.md, in stages that each fit one 10-minute device call.
# Run from the project root after `source benchmarks/gpu_setup.sh`; results go to $OUT.
#   bash benchmarks/gpu_runs.sh STAGE
set -uo pipefail
out=${OUT:-results/gpu}; mkdir -p "$out"
TIMEFORMAT='wall %R s'
ev() { local name=$1; shift; { time python3 -m openral_mjx.eval "$@" --out "$out/$name.json" --no-breakdown; } 2>&1 | grep -v "^  " | tail -4; }
case ${1:?stage} in
  warp-push)   # issue 7 / 2: tabletop_push on warp vs raw Warp and 16-core C; 100k seeds (issue 6)
    python3 -m openral_mjx.bench --backend warp --n 4096 16384 65536 --out "$out/bench_warp_push.json"
    ev push_warp_100k --backend warp --n-envs 50000 --n-episodes 100000
    ls -l "$out/push_warp_100k.json" ;;
  warp-box)    # issue 7: so101_box on warp vs raw Warp and C; agreement run
    python3 -m openral_mjx.bench --scene so101_box --backend warp --n 4096 16384 65536 \
      --c-max-envs 1024 --out "$out/bench_warp_box.json"
    ev box_warp_4096 --scene so101_box --backend warp --n-envs 4096
    ev box_c_4096 --scene so101_box --backend c --n-envs 4096 ;;
  mjx-box)     # issue 4: so101_box scripted and zero on MJX over 4,096 seeds
    ev box_mjx_4096 --scene so101_box --backend mjx --n-envs 4096
    ev box_mjx_zero_4096 --scene so101_box --backend mjx --n-envs 4096 --policy zero
    for a in c warp; do python3 -m openral_mjx.compare "$out/box_${a}_4096.json" \
      "$out/box_mjx_4096.json" --unpaired --test two-proportion-z --confidence 0.99; done ;;
  mjx-box-bench)  # issue 4: evaluator vs raw MJX on so101_box
    python3 -m openral_mjx.bench --scene so101_box --backend mjx --n 1024 4096 16384 \
      --c-max-envs 1024 --out "$out/bench_mjx_box.json" ;;
  mjx-warm)    # issue 7: cold and warm start of an mjx eval (compilation + traced-episode caches)
    for i in 1 2; do ev push_mjx_4096_$i --backend mjx --n-envs 4096; done
    ev push_warp_4096 --backend warp --n-envs 4096
    python3 -m openral_mjx.compare "$out/push_mjx_4096_2.json" "$out/push_warp_4096.json" \
      --unpaired --test two-proportion-z --confidence 0.99 ;;
  *) echo "unknown stage $1"; exit 2 ;;
esac
