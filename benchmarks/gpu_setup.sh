#!/usr/bin/env bash
# Source on the GPU machine (see ../shared/GPU.md): installs the wheels carried in .gpu/ and,
# once its three parts have arrived in /tmp/warp-parts, warp-lang; sets PYTHONPATH.
#   part N of warp:   WARP_PART=N source benchmarks/gpu_setup.sh   (carry .warpN)
#   later calls:      source benchmarks/gpu_setup.sh
set -e
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
if [ -d .gpu ] && [ ! -f /tmp/site/.gpu-done ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site .gpu/*.whl
  touch /tmp/site/.gpu-done
fi
if [ -n "${WARP_PART:-}" ]; then
  mkdir -p /tmp/warp-parts && cp .warp"$WARP_PART"/* /tmp/warp-parts/
fi
if [ -f /tmp/warp-parts/NAME ] && [ -f /tmp/warp-parts/part.00 ] && [ -f /tmp/warp-parts/part.01 ] \
   && [ ! -f /tmp/site/.warp-done ]; then
  (cd /tmp/warp-parts && cat part.0* > "$(cat NAME)" && sha256sum -c SHA256 \
   && python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site "$(cat NAME)")
  touch /tmp/site/.warp-done
fi
set +e
