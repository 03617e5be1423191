#!/usr/bin/env bash
# The GPU measurements behind BENCHMARKS.md, in stages that each fit one 10-minute device call.
# Run from the project root after `source benchmarks/gpu_setup.sh`; results go to $OUT.
#   bash benchmarks/gpu_runs.sh STAGE
set -uo pipefail
out=${OUT:-results/gpu}; mkdir -p "$out"
TIMEFORMAT='wall %R s'
# each run's whole output is also kept in $out/NAME.log: a call cut at its time limit still
# brings back what the run printed (the summary lines alone come at the end)
ev() { local name=$1; shift; { time python3 -m openral_mjx.eval "$@" --out "$out/$name.json" --no-breakdown; } 2>&1 | tee "$out/$name.log" | grep -v "^  " | tail -4; }
# NVIDIA's MPS daemon (MPS=1): lets processes on one GPU run their kernels side by side
mps_start() { [ "${MPS:-0}" = 1 ] || return 0
  export CUDA_MPS_PIPE_DIRECTORY=/tmp/mps-pipe CUDA_MPS_LOG_DIRECTORY=/tmp/mps-log
  # a daemon left by an earlier call that was stopped is reused, not an error
  mkdir -p /tmp/mps-pipe /tmp/mps-log && { nvidia-cuda-mps-control -d 2>/dev/null \
    || [ -e /tmp/mps-pipe/control ]; }; }
mps_stop() { [ "${MPS:-0}" = 1 ] && echo quit | nvidia-cuda-mps-control; return 0; }
# libero_policy P: $policy and $opts (scene options) for P: act (the random-weight ACT on two
# IMAGE px cameras, made once), mlp (a random-weight JAX MLP on the 8-D state), expert
libero_policy() {
  case $1 in
    act) [ -d /tmp/act_libero ] || python3 benchmarks/libero_act_policy.py \
           --out /tmp/act_libero --size "${IMAGE:-128}" | tail -1
         policy=lerobot:/tmp/act_libero; opts=() ;;
    mlp) [ -d /tmp/mlp_libero ] || python3 benchmarks/libero_mlp_policy.py \
           --out /tmp/mlp_libero | tail -1
         policy=mlp:/tmp/mlp_libero; opts=(expert=false) ;;
    expert) policy=libero-expert; opts=() ;;
    *) echo "unknown policy $1 (act, mlp, expert)"; return 2 ;;
  esac
}
mw_tasks() { python3 -c "from openral_mjx.scenes import scene_suite as s; print(*s('metaworld_mjx', '${SUITE:-mt10}'))"; }
case ${1:?stage} in
  mw-mirror)   # issue 20: MetaWorld mirror, SUITE (mt10) or TASKS x 1,000 seeds, JAX MLP in the loop
    for t in ${TASKS:-$(mw_tasks)}; do  # one process per task (compiled models freed between)
      python3 benchmarks/metaworld_mirror.py mirror --tasks "$t" --backend ${BACKEND:-warp} \
        --seeds 1000 --out "$out/metaworld_mirror.jsonl" | tail -1 | cut -c1-200
    done ;;
  mw-warm)     # issue 20: fill Warp's kernel cache and JAX's compilation cache for SUITE/TASKS,
               # PROCS processes at once (on warp the first task alone: the kernels every model
               # shares); each process's JSON lines go to $out/warm_I.jsonl
    tasks=(${TASKS:-$(mw_tasks)}); P=${PROCS:-8}; b=${BACKEND:-warp}; first=0
    export XLA_PYTHON_CLIENT_PREALLOCATE=false
    if [ "$b" = warp ]; then
      python3 benchmarks/metaworld_mirror.py mirror --tasks "${tasks[0]}" --seeds 1000 \
        --out "$out/warm_first.jsonl" | tail -1 | cut -c1-200; first=1
    fi
    for i in $(seq 0 $((P - 1))); do
      part=(); for ((j = first + i; j < ${#tasks[@]}; j += P)); do part+=("${tasks[j]}"); done
      [ ${#part[@]} -gt 0 ] && python3 benchmarks/metaworld_mirror.py mirror --tasks "${part[@]}" \
        --backend "$b" --seeds ${SEEDS:-1000} --out "$out/warm_$i.jsonl" > "$out/warm_$i.log" 2>&1 &
    done
    wait; tail -qn1 "$out"/warm_*.log | cut -c1-160 ;;
  mw-concurrent)  # issue 20: TASKS (the first 8 of MT50) at once, one process each, on one GPU,
                  # against the same processes one at a time; MPS=1 under NVIDIA's MPS daemon
    export XLA_PYTHON_CLIENT_PREALLOCATE=false; mps_start || exit 1
    python3 benchmarks/metaworld_mirror.py concurrent --tasks ${TASKS:-$(mw_tasks | cut -d' ' -f1-8)} \
      --backend ${BACKEND:-warp} --seeds ${SEEDS:-1000} --out "$out/metaworld_concurrent.jsonl" \
      | tail -1 | cut -c1-400
    mps_stop ;;
  mw-suite-cli)  # issue 20: what a user runs, SUITE (mt50) x 1,000 seeds through eval --suite, the
                 # random MLP as a checkpoint, TASK_PROCS tasks at once (MPS=1 under MPS)
    mps_start || exit 1
    python3 benchmarks/metaworld_mirror.py save-mlp --out /tmp/mw_mlp
    n=${TASK_PROCS:-16}; s=${SUITE:-mt50}
    { time python3 -m openral_mjx.eval --scene metaworld_mjx --suite "$s" --backend warp \
      --n-envs 1000 --policy mlp:/tmp/mw_mlp --task-processes "$n" --out /tmp/mw_suite.json \
      --no-breakdown; } 2>&1 | grep -v "^  " | tail -4
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); d['episodes']=len(d['episodes'])
json.dump(d, open(sys.argv[2], 'w'), indent=1)" /tmp/mw_suite.json "$out/mw_suite_${s}_k$n.json"
    mps_stop ;;
  mw-suite)    # issue 20: the whole suite in one process, 1,000 seeds per task (after mw-warm)
    python3 benchmarks/metaworld_mirror.py mirror --tasks ${TASKS:-${SUITE:-mt10}} --backend ${BACKEND:-warp} \
      --seeds 1000 --out "$out/metaworld_mirror_${SUITE:-mt10}.jsonl" | cut -c1-140 ;;
  mw-host)     # issue 20: MetaWorld itself on all cores, same tasks (its mujoco 3.3.0, .gpumw);
               # MODES picks host (through our adapter) and/or host-direct (MetaWorld alone)
    for m in ${MODES:-host host-direct}; do
      [ "$m" = host ] && n=${HOST_SEEDS:-32} || n=${DIRECT_SEEDS:-64}
      python3 benchmarks/metaworld_mirror.py "$m" --tasks ${TASKS:-$(mw_tasks)} --seeds "$n" \
        --workers "$(nproc)" --out "$out/metaworld_host.jsonl" | tail -2 | cut -c1-200
    done ;;
  mw-raw)      # issue 20: evaluator vs raw physics on the mirror, per task group (PROFILE=1:
               # a traced second run of each, GPU kernel time by kind in the row; issue 38)
    for t in ${TASKS:-reach-v3 push-v3 door-open-v3}; do
      python3 benchmarks/metaworld_mirror.py raw --tasks "$t" --backend ${BACKEND:-warp} \
        --n ${N:-4096 65536} --max-steps ${MAX_STEPS:-500} --out "$out/metaworld_raw.jsonl" \
        ${PROFILE:+--profile "$out/profile"} | tail -2 | cut -c1-250
    done ;;
  mw-poses-cost)  # issue 20: what observing the state the step ends in costs: the evaluator
                  # against raw physics with the fix and without it (--poses-before-step)
    for flag in "" --poses-before-step; do
      python3 benchmarks/metaworld_mirror.py raw --tasks ${TASKS:-door-open-v3} --backend warp \
        --n ${N:-4096 65536} --out "$out/metaworld_raw_poses.jsonl" $flag | tail -2 | cut -c1-250
    done ;;
  mw-mjx-check)  # issue 20: every task of SUITE (mt50) or TASKS builds, compiles and steps on
                 # mjx (JAX on this machine's CPU), against c: PROCS lanes side by side, one JSON
                 # line per task in MJX_DIR/mjx_check_I.jsonl as each finishes; a task past
                 # TASK_S seconds (1800) is given up. The tasks that simulate the hand reset per
                 # episode (slowest) go first, one per lane.
    export JAX_PLATFORMS=cpu; d=${MJX_DIR:-/tmp/mjxcheck}; mkdir -p "$d"
    tasks=(${TASKS:-$(python3 -c "from openral_mjx.scenes import scene_suite as s
from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS as T
ts = s('metaworld_mjx', '${SUITE:-mt50}'); print(*sorted(ts, key=lambda t: not T[t].hand_reset_per_episode))")})
    P=${PROCS:-16}
    for i in $(seq 0 $((P - 1))); do
      ( for ((j = i; j < ${#tasks[@]}; j += P)); do
          timeout "${TASK_S:-1800}" python3 benchmarks/metaworld_mirror.py mjx-check \
            --tasks "${tasks[j]}" --seeds 2 --max-steps 5 --out "$d/mjx_check_$i.jsonl" \
            >> "$d/log_$i.txt" 2>&1 || echo "${tasks[j]}: gave up or failed ($?)" >> "$d/log_$i.txt"
        done ) &
    done
    wait; cat "$d"/mjx_check_*.jsonl | wc -l ;;
  mw-mjx-peak)  # issue 38: mjx on the GPU, PROCS task processes at once (each plans for
                # 1/SHARE of the card, SHARE=PROCS by default, as a suite's task processes
                # do): per task the batch that fits SEEDS (1000) envs' request, XLA's
                # estimate, the allocator's peak, compile time
    tasks=(${TASKS:-$(mw_tasks)}); P=${PROCS:-10}
    export XLA_PYTHON_CLIENT_PREALLOCATE=false
    for i in $(seq 0 $((P - 1))); do
      ( for ((j = i; j < ${#tasks[@]}; j += P)); do
          timeout "${TASK_S:-540}" python3 benchmarks/metaworld_mirror.py mjx-peak --backend mjx \
            --tasks "${tasks[j]}" --seeds ${SEEDS:-1000} --max-steps ${MAX_STEPS:-5} --share "${SHARE:-$P}" \
            --out "$out/mjx_peak.jsonl" >> "$out/mjx_peak_$i.log" 2>&1 \
            || echo "${tasks[j]}: failed or cut ($?)" >> "$out/mjx_peak_$i.log"
        done ) &
    done
    wait; cut -c1-330 "$out/mjx_peak.jsonl"; grep -h "failed or cut" "$out"/mjx_peak_*.log ;;
  mw-agree)    # issue 20: the mirror on the GPU against MetaWorld on the CPU, same seeds
    python3 -m openral_mjx.benchmarks.metaworld.agreement --tasks ${TASKS:-reach-v3 push-v3 \
      pick-place-v3 door-open-v3 drawer-close-v3} --backend ${BACKEND:-warp} --seeds 500 \
      --traj-seeds 8 --workers "$(nproc)" --out "$out/metaworld_agreement_gpu.json" ;;
  mw-agree-c)  # issue 20: the agreement table on `c` on this machine's CPU cores, SUITE (mt50)
               # or TASKS: PROCS processes side by side, each on its own cores (taskset) with its
               # MetaWorld workers; one JSON per task in AGREE_DIR, a task already there skipped
               # (the stage can run in the background over several calls and be started again);
               # ENGINE=ours: MetaWorld's code on the mirror's mujoco
    export JAX_PLATFORMS=cpu; d=${AGREE_DIR:-/tmp/agree}; mkdir -p "$d"
    tasks=(${TASKS:-$(SUITE=${SUITE:-mt50} mw_tasks)}); P=${PROCS:-4}; per=$(( $(nproc) / P ))
    for i in $(seq 0 $((P - 1))); do
      ( for ((j = i; j < ${#tasks[@]}; j += P)); do
          t=${tasks[j]}; [ -f "$d/$t.json" ] && continue
          taskset -c $((i * per))-$((i * per + per - 1)) python3 -m \
            openral_mjx.benchmarks.metaworld.agreement --tasks "$t" --backend c --seeds ${SEEDS:-500} \
            --traj-seeds 4 --workers "$per" --engine ${ENGINE:-metaworld} --out "$d/$t.json" \
            >> "$d/log_$i.txt" 2>&1
        done ) &
    done
    wait; ls "$d"/*.json | wc -l ;;
  rand-test)   # issue 22: per-env physics fields on mjx and warp against MuJoCo C (GPU)
    python3 -m pytest -q -p no:cacheprovider tests/physics/test_per_env_fields.py -m "slow or not slow" \
      -k physics 2>&1 | tail -3 ;;
  rand-cost)   # issue 22: randomisation's cost on tabletop_push, nominal vs 9 factors, 4,096 envs
    R="friction=0.3:1.2 mass=0.5x:2x kp=0.7x:1.3x damping=0.5x:2x armature=0.5x:2x delay=0:2"
    R="$R action_noise=0:0.02 joint_noise=0:0.005 object_noise=0:0.003"
    for b in ${BACKENDS:-warp mjx}; do
      for scene in ${SCENES:-tabletop_push}; do
        ev ${scene}_${b}_nominal --scene $scene --backend $b --n-envs 4096 --n-episodes 16384 --batching chunks
        ev ${scene}_${b}_random --scene $scene --backend $b --n-envs 4096 --n-episodes 16384 \
          --batching chunks --randomize $R
      done
    done ;;
  rand-mirror)  # issue 22: the MetaWorld mirror randomised on the GPU, its expert, same seeds
    R="mass=0.5x:2x friction=0.3:1.0 delay=0:2 object_noise=0:0.005"
    for t in ${TASKS:-push-v3}; do
      ev mw_${t}_nominal --scene metaworld_mjx --task $t --policy metaworld-expert \
        --backend ${BACKEND:-warp} --n-envs ${N:-256} --batching chunks
      ev mw_${t}_random --scene metaworld_mjx --task $t --policy metaworld-expert \
        --backend ${BACKEND:-warp} --n-envs ${N:-256} --batching chunks --randomize $R
    done ;;
  rand-sweep)  # issue 22: a robustness curve on the GPU, the same 4,096 seeds at each value
    ev push_sweep_${FACTOR:-friction} --backend ${BACKEND:-warp} --n-envs 4096 \
      --sweep ${SWEEP:-friction=0.02:0.62:7} ;;
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
    python3 -m openral_mjx.bench --scene so101_box --backend mjx --n ${N:-1024 4096 16384} \
      --c-max-envs 1024 --out "$out/bench_mjx_box${N:+_${N// /_}}.json" ;;
  mjx-warm)    # issue 7: cold and warm start of an mjx eval (compilation + traced-episode caches)
    for i in 1 2; do ev push_mjx_4096_$i --backend mjx --n-envs 4096; done
    for i in 1 2; do ev push_warp_4096_$i --backend warp --n-envs 4096; done
    python3 -m cProfile -s cumtime -m openral_mjx.eval --backend mjx --n-envs 4096 \
      --out "$out/push_mjx_4096_3.json" --no-breakdown 2>&1 | head -45 | cut -c1-150
    python3 -m openral_mjx.compare "$out/push_mjx_4096_2.json" "$out/push_warp_4096_2.json" \
      --unpaired --test two-proportion-z --confidence 0.99 ;;
  warp-million)  # issue 7 / 5: one million seeds in one command on one GPU, peak memory
    { time python3 benchmarks/peak_memory.py --backend warp --n-envs 65536 --n-episodes 1000000 \
      --out /tmp/push_warp_1m.json --no-breakdown; } 2>&1 | grep -v "^  " | tail -6
    ls -l /tmp/push_warp_1m.json  # too big to bring back: keep all but the episodes
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); d['episodes']=len(d['episodes'])
json.dump(d, open(sys.argv[2], 'w'), indent=1)" /tmp/push_warp_1m.json "$out/push_warp_1m.json" ;;
  scale)       # issue 7 / 3: one GPU vs all local GPUs at N = 65,536 (strong) and 2 x 65,536
    b=${BACKEND:-warp}; k=${CHUNKS:-2}  # chunks per run (mjx: 1, to fit one call)
    CUDA_VISIBLE_DEVICES=0 ev scale_${b}_1gpu_65536 --backend "$b" --n-envs 65536 \
      --n-episodes $((k * 65536))
    ev scale_${b}_all_65536 --backend "$b" --n-envs 65536 --n-episodes $((k * 65536))
    [ "${WEAK:-1}" = 1 ] && ev scale_${b}_all_131072 --backend "$b" --n-envs 131072 \
      --n-episodes $((k * 131072)) ;;
  scale-procs)  # issue 7 / 3: all local GPUs as one process each (eval --processes), same sizes
    b=${BACKEND:-warp}; k=${CHUNKS:-2}; p=$(nvidia-smi -L | grep -c "^GPU ")
    ev scale_${b}_procs_65536 --backend "$b" --processes "$p" --n-envs 65536 \
      --n-episodes $((k * 65536))
    [ "${WEAK:-1}" = 1 ] && ev scale_${b}_procs_131072 --backend "$b" --processes "$p" \
      --n-envs 131072 --n-episodes $((k * 131072)) ;;
  mjx-push-bench)  # issue 7 / 6: tabletop_push evaluator vs raw MJX and C
    python3 -m openral_mjx.bench --backend mjx --n ${N:-4096 16384 65536} \
      --out "$out/bench_mjx_push${N:+_${N// /_}}.json" ;;
  rays)        # issue 5: ray-cast sensors vs raw vmap(mjx.ray) and 16-core mj_multiRay, geom sweep
    python3 -m openral_mjx.bench --rays --scene so101_box --n 1024 4096 \
      --out "$out/bench_rays_box.json" ;;
  rays-push)   # issue 5: the same on tabletop_push (~10 geoms in view; its laser mostly misses)
    python3 -m openral_mjx.bench --rays --scene tabletop_push --n 1024 4096 --geom-counts 8 \
      --out "$out/bench_rays_push.json" ;;
  rays-eval-mjx)   # issue 5: so101_box at 4,096 envs, overhead depth (ray cast) off / on / CNN
    d=(--scene so101_box --backend mjx --n-envs 4096)
    ev box_mjx_nodepth "${d[@]}"
    ev box_mjx_depth "${d[@]}" --opt 'obs_depth_cameras=[overhead]'
    ev box_mjx_depthcnn "${d[@]}" --opt 'obs_depth_cameras=[overhead]' --policy depth_cnn \
      --frames 2 ;;
  rays-eval-warp)  # issue 5: the same on warp (depth from MuJoCo-Warp's renderer) + agreement
    d=(--scene so101_box --backend warp --n-envs 4096)
    ev box_warp_nodepth "${d[@]}"
    ev box_warp_depth "${d[@]}" --opt 'obs_depth_cameras=[overhead]'
    ev box_warp_depthcnn "${d[@]}" --opt 'obs_depth_cameras=[overhead]' --policy depth_cnn \
      --frames 2
    python3 benchmarks/depth_agreement.py --n 1024 --steps 20 ;;
  arms)        # issue 17: the scripted expert on the published-style test arms, 256 seeds each
    b=${BACKEND:-mjx}
    ev arm_small6_$b --backend "$b" --n-envs 256 --robot-mjcf tests/data/arms/small6.xml \
      --opt ee_site=tool0
    ev arm_industrial6_$b --backend "$b" --n-envs 256 \
      --robot-mjcf tests/data/arms/industrial6.xml --opt ee_site=attachment_site
    ev arm_seven_$b --backend "$b" --n-envs 256 --robot-mjcf tests/data/arms/seven.xml \
      --opt ee_site=tcp ;;
  batching)    # issue 18: refill vs chunks in episodes/s at one N (SCENE, N, EPISODES, CHUNK)
    s=${SCENE:-tabletop_push}; n=${N:-65536}
    python3 -m openral_mjx.bench --batching --scene "$s" --backend warp --n "$n" \
      --episodes "${EPISODES:-1000000}" --chunk-episodes "${CHUNK:-131072}" \
      --out "$out/batching_${s}_${n}.json" ;;
  libero-speed)  # issue 37: the LIBERO mirror's evaluator against its raw physics, TASKS (one per
                 # suite) at NS envs; EXTRA passes more flags (--ccd-contacts-per-env ...)
    python3 benchmarks/libero_mirror_gpu.py \
      --tasks ${TASKS:-libero_spatial/0 libero_object/0 libero_goal/1 libero_10/0} \
      --ns ${NS:-4096} --steps ${STEPS:-30} ${EXTRA:-} --out "$out/libero_speed${TAG:-}.json" ;;
  libero-suite-cli)  # issues 37/42: the standard protocol as a user runs it, each of SUITES x 50
                     # initial states through eval --suite, POLICY (random: every episode runs to
                     # the suite's step limit; mlp: benchmarks/libero_mlp_policy.py's random MLP
                     # on the state), TASK_PROCS tasks at once (MPS=1 under MPS)
    mps_start || exit 1
    policy=${POLICY:-random}; opts=()
    if [ "$policy" = mlp ]; then
      [ -d /tmp/mlp_libero ] || python3 benchmarks/libero_mlp_policy.py --out /tmp/mlp_libero | tail -1
      policy=mlp:/tmp/mlp_libero; opts=(--opt expert=false)
    fi
    for s in ${SUITES:-libero_spatial libero_object libero_goal libero_10}; do
      { time python3 -m openral_mjx.eval --scene libero_mjx --suite "$s" --backend warp \
        --n-envs 50 --policy "$policy" "${opts[@]}" --task-processes "${TASK_PROCS:-10}" \
        --out "/tmp/libero_suite_$s.json" --no-breakdown; } 2>&1 | tee "$out/libero_suite_$s.log" \
        | grep -v "^  " | tail -4
      python3 -c "import json,sys; d=json.load(open(sys.argv[1])); d['episodes']=len(d['episodes'])
json.dump(d, open(sys.argv[2], 'w'), indent=1)" "/tmp/libero_suite_$s.json" \
        "$out/libero_suite_${s}_k${TASK_PROCS:-10}.json"
    done
    mps_stop ;;
  libero-suites-at-once)  # issue 42: the four suites' standard protocol with every suite's eval
                          # started at once (TASK_PROCS tasks each, all under MPS), POLICY as in
                          # libero-suite-cli or act (libero-act's ACT on two cameras); each
                          # suite's report and output go to $out/at_once
    policy=${POLICY:-random}; opts=()
    if [ "$policy" = mlp ]; then
      [ -d /tmp/mlp_libero ] || python3 benchmarks/libero_mlp_policy.py --out /tmp/mlp_libero | tail -1
      policy=mlp:/tmp/mlp_libero; opts=(--opt expert=false)
    elif [ "$policy" = act ]; then  # two IMAGE px cameras: the tasks' visual files must be there
      [ -d /tmp/act_libero ] || python3 benchmarks/libero_act_policy.py --out /tmp/act_libero \
        --size "${IMAGE:-128}" | tail -1
      policy=lerobot:/tmp/act_libero; opts=(--opt "image_size=${IMAGE:-128}")
    fi
    MPS=1; mps_start || exit 1; mkdir -p "$out/at_once"
    time (for s in ${SUITES:-libero_spatial libero_object libero_goal libero_10}; do
      python3 -m openral_mjx.eval --scene libero_mjx --suite "$s" --backend warp --n-envs 50 \
        --policy "$policy" "${opts[@]}" --task-processes "${TASK_PROCS:-10}" \
        --out "$out/at_once/libero_suite_$s.json" --no-breakdown > "$out/at_once/$s.log" 2>&1 &
    done; wait)
    grep -h "success" "$out"/at_once/*.log | cut -c1-200
    mps_stop ;;
  libero-four-suites)  # issue 42: the four suites' standard protocol as one eval (`--suite` with
                       # the four, comma-separated: one pool of TASK_PROCS task processes over the
                       # 40 tasks, under MPS), POLICY as in libero-suites-at-once
    policy=${POLICY:-random}; opts=()
    if [ "$policy" = act ]; then
      [ -d /tmp/act_libero ] || python3 benchmarks/libero_act_policy.py --out /tmp/act_libero \
        --size "${IMAGE:-128}" | tail -1
      policy=lerobot:/tmp/act_libero; opts=(--opt "image_size=${IMAGE:-128}")
    fi
    MPS=1; mps_start || exit 1
    ev libero_four_suites --scene libero_mjx --backend warp --n-envs 50 --policy "$policy" \
      "${opts[@]}" --task-processes "${TASK_PROCS:-16}" \
      --suite libero_spatial,libero_object,libero_goal,libero_10
    mps_stop ;;
  libero-cams)  # issue 42: LIBERO's two cameras on warp (MuJoCo-Warp's renderer, IMAGE px)
                # against the same run without them: TASK at NS envs, STEPS control steps,
                # random policy, fixed chunks (every episode runs to STEPS)
    for n in ${NS:-1024}; do
      common=(--scene libero_mjx --task "${TASK:-libero_object/0}" --backend warp --n-envs "$n"
              --policy random --max-steps "${STEPS:-100}" --batching chunks)
      ev "libero_cams_none_$n" "${common[@]}"
      ev "libero_cams_${IMAGE:-128}px_$n" "${common[@]}" --opt "image_size=${IMAGE:-128}"
    done ;;
  libero-act)  # issue 42: a random-weight ACT at lerobot's default size (two IMAGE px cameras,
               # benchmarks/libero_act_policy.py) in process on the GPU, each of SUITES x 50
               # initial states through eval --suite (TASK_PROCS at once, MPS=1 under MPS), or
               # TASK alone when SUITES is unset
    [ -d /tmp/act_libero ] || python3 benchmarks/libero_act_policy.py --out /tmp/act_libero \
      --size "${IMAGE:-128}" | tail -1
    if [ -z "${SUITES:-}" ]; then
      ev "libero_act_$(echo "${TASK:-libero_object/0}" | tr / _)" --scene libero_mjx \
        --task "${TASK:-libero_object/0}" --backend warp --n-envs 50 --policy lerobot:/tmp/act_libero
    else
      mps_start || exit 1
      for s in $SUITES; do
        { time python3 -m openral_mjx.eval --scene libero_mjx --suite "$s" --backend warp \
          --n-envs 50 --policy lerobot:/tmp/act_libero --opt "image_size=${IMAGE:-128}" \
          --task-processes "${TASK_PROCS:-10}" \
          --out "/tmp/libero_act_$s.json" --no-breakdown; } 2>&1 | grep -v "^  " | tail -4
        python3 -c "import json,sys; d=json.load(open(sys.argv[1])); d['episodes']=len(d['episodes'])
json.dump(d, open(sys.argv[2], 'w'), indent=1)" "/tmp/libero_act_$s.json" "$out/libero_act_suite_$s.json"
      done
      mps_stop
    fi ;;
  libero-startup)  # issue 42: a task process's start-up (build, trace, compile) with ACT in the
                   # loop, TASK at 50 envs, run twice (the second finds JAX's compilation cache
                   # warm; the two trees' programs differ, so neither finds the other's), for
                   # this tree and, side by side, the package under BASE (an older checkout's
                   # root, e.g. from `git archive`) when given
    [ -d /tmp/act_libero ] || python3 benchmarks/libero_act_policy.py --out /tmp/act_libero \
      --size "${IMAGE:-128}" | tail -1
    t=${TASK:-libero_object/0}; out=$(realpath "$out"); here=$PWD
    for root in ${BASE:-} "$here"; do
      tag=$([ "$root" = "$here" ] && echo tree || echo base)
      for run in cold warm; do  # from ROOT: `python -m` puts the working directory first
        echo "== $tag $run"
        (cd "$root" && PYTHONPATH=/tmp/site:$root ev "libero_startup_${tag}_$run" \
          --scene libero_mjx --task "$t" --backend warp --n-envs 50 --policy lerobot:/tmp/act_libero)
      done
    done ;;
  libero-task-profile)  # issue 42: where one task process's time and CPU go (ACT on two IMAGE
                        # px cameras, TASK at 50 envs): benchmarks/profile_eval.py twice (cold,
                        # then with JAX's cache warm), each with PROCS-1 copies of the same run
                        # beside it (default 1: alone) to load the CPU as a pool would
    libero_policy act || exit 2
    t=${TASK:-libero_object/0}
    args=(--scene libero_mjx --task "$t" --backend warp --n-envs 50 --policy "$policy"
          --opt "image_size=${IMAGE:-128}" --no-breakdown)
    for run in cold warm; do
      for i in $(seq 2 "${PROCS:-1}"); do
        python3 -m openral_mjx.eval "${args[@]}" --out "/tmp/beside_$i.json" > /dev/null 2>&1 &
      done
      python3 benchmarks/profile_eval.py --prof-out "$out/task_profile_$run.pstats" -- "${args[@]}" \
        --out "$out/task_profile_$run.json" > "$out/task_profile_$run.txt" 2>&1
      wait; head -40 "$out/task_profile_$run.txt" | grep -v "^  *[0-9]* *[0-9.]* *[0-9.]* *[0-9.]"
    done ;;
  libero-mass)  # issue 42: the mass-seed protocol (--opt protocol=sampled) on TASKS (default
                # libero_object/0), N seeds at once (default 1,024), per POLICIES (default
                # "act expert"): act, the random-weight ACT on two IMAGE px cameras; mlp, a
                # random-weight JAX MLP on the 8-D state; expert, libero-expert on the state.
                # Each task's draws come with its export. EXTRA passes more flags
                # (--contacts-per-env 512: libero_10/0's two cans in the basket overflow 256)
    n=${N:-1024}
    for t in ${TASKS:-${TASK:-libero_object/0}}; do
      tag=$(echo "$t" | tr / _)
      for p in ${POLICIES:-act expert}; do
        libero_policy "$p" || exit 2
        ev "libero_mass_${p}_${tag}_$n${TAG:-}" --scene libero_mjx --task "$t" --backend warp \
          --n-envs "$n" --policy "$policy" --opt protocol=sampled "sampled_states=$n" "${opts[@]}" \
          ${EXTRA:-}
      done
    done ;;
  libero-host)  # issue 42: the baseline of libero-mass, LIBERO itself through the host adapter
                # on this machine's cores (one env worker per core; after gpu_setup.sh with
                # .lh1-.lh3, .gl and .libero_models carried), the same TASKS, POLICIES and
                # drawn states, HOST_N seeds (default 64) from seed 0, cameras as the policy
                # needs (IMAGE px for act; none otherwise, LIBERO rendering nothing, as the
                # mirror without cameras)
    k=$(nproc)
    for t in ${TASKS:-${TASK:-libero_object/0}}; do
      tag=$(echo "$t" | tr / _)
      for p in ${POLICIES:-act expert}; do
        libero_policy "$p" || exit 2
        [ "$p" = act ] && size=${IMAGE:-128} || size=null
        MUJOCO_GL=egl ev "libero_host_${p}_${tag}_${HOST_N:-64}" --scene libero --task "$t" \
          --n-envs "$k" --n-episodes "${HOST_N:-64}" --policy "$policy" --opt protocol=sampled \
          "sampled_states=${N:-1024}" "n_workers=$k" "image_size=$size" "${opts[@]}"
      done
    done ;;
  libero-agreement)  # issue 37: the expert's closed-loop agreement rows on this machine's cores:
                     # TASKS x SEEDS (200) drawn states, LIBERO through the host adapter (one
                     # worker per core) against the mirror on BACKEND (c, its threads on the
                     # same cores), after gpu_setup.sh with .lh1-.lh3 and .gl carried. Exports
                     # and draws are made here by LIBERO's worker where none were carried
                     # (~25 s a task, ~2.5 s a draw per core); each task's row goes to
                     # /tmp/rows_agreement.json as it ends (copied to $out), both reports to
                     # $out. A later call with the same TASKS resumes: rows already made are
                     # kept, not run again. A libero_10 task takes ~8.5 min (LIBERO's 16
                     # workers: 89 s start, 292 s of episodes; the mirror 123 s), so LIMIT
                     # (default 560 s) stops the run inside the call and keeps what ended
    timeout "${LIMIT:-560}" python3 -m openral_mjx.benchmarks.libero.agreement \
      --tasks ${TASKS:?TASKS} --seeds "${SEEDS:-200}" --protocol sampled --host-envs "$(nproc)" \
      --mirror-envs "${MIRROR_ENVS:-${SEEDS:-200}}" --backend "${BACKEND:-c}" \
      --out /tmp/rows_agreement.json --resume --reports "$out" 2>&1 | tee "$out/agreement.log" \
      | grep -v "^  " | tail -"$(( $(echo $TASKS | wc -w) + 4 ))"
    cp /tmp/rows_agreement.json "$out/" 2>/dev/null ;;
  libero-warp-options)  # issue 37: TASK (libero_10/0)'s expert on warp at 200 drawn states under
                        # CONFIGS of mjOption changes (benchmarks/libero_warp_options.py): which
                        # keep its episodes finite (22 of 200 went non-finite on LIBERO's own);
                        # ~90 s a config, one report each (.lm with the task's 200 draws carried)
    python3 benchmarks/libero_warp_options.py --task "${TASK:-libero_10/0}" --out "$out" \
      --contacts "${CONTACTS:-512}" \
      --config ${CONFIGS:-base ccd_iterations=200 ccd_tolerance=1e-4 cone=pyramidal} 2>&1 \
      | tee "$out/warp_options.log" | grep '^{' ;;
  cluster-scaling)  # issue 39: SUITE (mt10) over Ray vs --task-processes on this machine's GPUs,
                    # then HOST_SCENE (libero) over Ray actors vs local workers up to its cores.
                    # Needs the ray extra (its wheels carried: the machine has no network) and,
                    # for the host part, the scene's worker environment (else PARTS=suite)
    python3 benchmarks/cluster_scaling.py --parts ${PARTS:-suite host} --suite ${SUITE:-mt10} \
      --backend ${BACKEND:-warp} --n-envs ${N:-1000} --n-episodes ${N:-1000} \
      --host-scene ${HOST_SCENE:-libero} --host-task ${HOST_TASK:-libero_spatial/0} \
      --host-n ${HOST_N:-64} --host-steps ${HOST_STEPS:-100} --out "$out/cluster_scaling.jsonl" \
      | grep -v '^{' ;;
  *) echo "unknown stage $1"; exit 2 ;;
esac
