#!/usr/bin/env bash
# Wheels for lerobot in the evaluator's process on the GPU machine (Python 3.12; its image has
# torch 2.11, torchvision 0.26, huggingface_hub, safetensors, Pillow, PyYAML): lerobot 0.6.1
# with --no-deps and the packages it imports at start that the image lacks. opencv alone is
# 60 MB, so it gets its own folder (its own call). Run from the project root; creates the
# git-ignored .gpulr/ and .gpucv/, which benchmarks/gpu_setup.sh installs.
set -euo pipefail
PLAT=(--platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64)
dl() { python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp "${PLAT[@]}" -d "$1" "${@:2}"; }
for d in .gpulr .gpucv; do grep -qx "/$d/" .git/info/exclude 2>/dev/null || echo "/$d/" >> .git/info/exclude; done
rm -rf .gpulr .gpucv && mkdir -p .gpulr .gpucv
dl .gpulr "lerobot==0.6.1" "draccus==0.11.*" mergedeep pyyaml-include toml typing-inspect mypy-extensions \
  "einops==0.8.*" gymnasium farama-notifications cloudpickle termcolor
dl .gpucv "opencv-python-headless<4.14"
du -sh .gpulr .gpucv
