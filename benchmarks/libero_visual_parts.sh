#!/usr/bin/env bash
# The visual files (meshes, textures) of LIBERO's four suites' 40 tasks, for cameras on a GPU
# machine that has no LIBERO environment: bundled into the export cache under
# OPENRAL_MJX_LIBERO_MODELS (default .libero_models, which calls carry) by exporting each task
# with its visual geoms, then packed as PARTS (default 3) xz-compressed tar parts of about equal
# size in the git-ignored .vis1/, .vis2/, ... (one call's carry each, ~35 MB at 3: two parts
# of ~50-56 MB left too little room for the working tree in a call's 64 MiB), which
# benchmarks/gpu_setup.sh unpacks there. Run from the project root, with the lerobot-libero
# worker environment built (`python -m openral_mjx.host.envs create lerobot-libero`).
set -euo pipefail
export OPENRAL_MJX_LIBERO_MODELS=${OPENRAL_MJX_LIBERO_MODELS:-$PWD/.libero_models}
python - <<'PY'
from openral_mjx.benchmarks.libero.assets import load_task, physics_spec
from openral_mjx.scenes import scene_suite

for suite in ("libero_spatial", "libero_object", "libero_goal", "libero_10"):
    for task in scene_suite("libero_mjx", suite):
        physics_spec(load_task(task), visuals=True)  # copies the task's files into files/
PY
cd "$OPENRAL_MJX_LIBERO_MODELS"
# largest first, each to the lightest part
parts=${PARTS:-3}
rm -f /tmp/vis_part*.txt
find files -type f -printf "%s %p\n" | sort -rn | awk -v n="$parts" '
  { k = 1; for (i = 2; i <= n; i++) if (size[i] < size[k]) k = i
    size[k] += $1; print $2 > ("/tmp/vis_part" k ".txt") }'
cd - > /dev/null
for i in $(seq 1 "$parts"); do
  grep -qx "/.vis$i/" .git/info/exclude 2>/dev/null || echo "/.vis$i/" >> .git/info/exclude
  rm -rf ".vis$i" && mkdir ".vis$i"
  tar cf - -C "$OPENRAL_MJX_LIBERO_MODELS" -T "/tmp/vis_part$i.txt" | xz -9 -T0 > ".vis$i/vis$i.tar.xz"
done
du -sh .vis*
