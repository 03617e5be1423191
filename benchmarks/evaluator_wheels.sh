#!/usr/bin/env bash
# Wheels for the evaluator's own small dependencies that the GPU machine's image lacks (Python
# 3.12): pydantic (reports are validated when read) and rich (the CLI's output), with what they
# import, and flatbuffers (jax.export). Without them `python -m openral_mjx.eval` fails there at
# import. Run from the project root; creates the git-ignored .gpust/ (~3 MB), which
# benchmarks/gpu_setup.sh installs: carry it in any call before the first run.
set -euo pipefail
grep -qx "/.gpust/" .git/info/exclude 2>/dev/null || echo "/.gpust/" >> .git/info/exclude
rm -rf .gpust && mkdir -p .gpust
# with their dependencies, so that pydantic-core is the one pydantic pins
python3 -m pip download -q --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .gpust \
  "pydantic>=2" rich flatbuffers
du -sh .gpust
