#!/usr/bin/env bash
# Wheels for the MetaWorld GPU measurements (benchmarks/gpu_runs.sh stages mw-*), after
# ../shared/tools/device_wheels.sh (WITH_WARP=1) has filled .gpu and .warp1-3. Run from the
# project root. Creates git-ignored folders, each under one call's 64 MiB beside the tree:
#   .gpumw/  MetaWorld 3.1.1 with its mujoco 3.3.0 and pure-Python deps (Python 3.12)
#   .gpu2/   mujoco-mjx, tyro, trimesh and their deps, moved out of .gpu so that .gpu fits
#            beside .warp3 in the last of the five calls:
#            .gpumw + .gpu2, .warp1, .warp2, .warp3, .gpu (then run), in quick succession.
set -euo pipefail
PLAT=(--platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64)
dl() { python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp "${PLAT[@]}" -d "$1" "${@:2}"; }
for d in .gpumw .gpu2; do grep -qx "/$d/" .git/info/exclude 2>/dev/null || echo "/$d/" >> .git/info/exclude; done
rm -rf .gpumw && mkdir -p .gpumw .gpu2
dl .gpumw metaworld==3.1.1 mujoco==3.3.0 gymnasium==1.4.0 farama-notifications cloudpickle \
  absl-py etils glfw pyopengl fsspec typing_extensions zipp imageio packaging pillow
for w in .gpu/mujoco_mjx-*.whl .gpu/tyro-*.whl .gpu/trimesh-*.whl .gpu/docstring_parser-*.whl \
  .gpu/typeguard-*.whl; do [ -f "$w" ] && mv "$w" .gpu2/; done
du -sh .gpu .gpu2 .gpumw
