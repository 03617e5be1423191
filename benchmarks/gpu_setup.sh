#!/usr/bin/env bash
# Source on the GPU machine (see ../shared/GPU.md): installs the wheels carried in .gpu/ and,
# once its three parts have arrived in /tmp/warp-parts, warp-lang; sets PYTHONPATH.
#   part N of warp:   WARP_PART=N source benchmarks/gpu_setup.sh   (carry .warpN; the wheel's
#                     parts may be re-split into more, smaller ones: the last brings NAME)
#   later calls:      source benchmarks/gpu_setup.sh
# Source it without a pipe (`source ... | tail` runs it in a subshell, which exports nothing to
# the command after it); send its output to a file instead.
set -e
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
# The machine's image sets PYTHONDONTWRITEBYTECODE=1 and its packages (and ours, installed with
# --no-compile) come without bytecode, so every Python process compiled ~3,400 modules from
# source: 32-38 s to import the evaluator and lerobot, against 14-17 s once they are cached
# (2026-11-29). An installed machine keeps bytecode; here it goes to /tmp/pyc (the image's
# site-packages may not be writable), and the first process to import a module writes it.
unset PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX=/tmp/pyc
# .gpu may come split over calls (.gpu, .gpu2; .gpu3: brax for finetune; .gpulr: lerobot 0.6.1
# and the small packages it imports that the image lacks; .gpucv: opencv-python-headless, which
# lerobot imports at start; .gpust: pydantic, rich and flatbuffers, which the evaluator imports)
# to fit beside the rest. Fetch .gpulr and .gpucv with benchmarks/lerobot_wheels.sh, .gpust
# with benchmarks/evaluator_wheels.sh.
for d in .gpu .gpu2 .gpu3 .gpulr .gpucv .gpust; do
  if [ -d "$d" ] && [ ! -f "/tmp/site/$d-done" ]; then
    # each set to its own folder, then merged: pip --target skips a package folder that is
    # already there (mujoco/ holds both mujoco's and mujoco-mjx's files)
    python3 -m pip install -q --no-index --no-deps --no-compile --target "/tmp/site$d" "$d"/*.whl \
      && mkdir -p /tmp/site && cp -r "/tmp/site$d"/. /tmp/site/ && touch "/tmp/site/$d-done"
  fi
done
if [ -n "${WARP_PART:-}" ]; then
  mkdir -p /tmp/warp-parts && cp .warp"$WARP_PART"/* /tmp/warp-parts/
fi
if [ -f /tmp/warp-parts/NAME ] && [ -f /tmp/warp-parts/part.00 ] && [ -f /tmp/warp-parts/part.01 ] \
   && [ ! -f /tmp/site/.warp-done ]; then
  # a part still missing (carried out of order) fails the checksum: said, not fatal, so the
  # rest of this call's setup still runs
  if (cd /tmp/warp-parts && cat part.0* > "$(cat NAME)" && sha256sum --quiet -c SHA256 \
      && python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site \
        "$(cat NAME)"); then
    touch /tmp/site/.warp-done
  else
    echo "warp-lang: its parts in /tmp/warp-parts do not make the wheel yet; not installed" >&2
  fi
fi
# Warp's kernel cache from an earlier machine (same warp-lang, same GPU arch), if carried as
# .warpcache/warpcache.tgz: saves the first run's ~5 min kernel build. Warp checks each
# kernel's hash, so a stale entry is rebuilt, never used.
if [ -f .warpcache/warpcache.tgz ] && [ ! -d ~/.cache/warp ]; then
  mkdir -p ~/.cache && tar xzf .warpcache/warpcache.tgz -C ~/.cache
fi
# LIBERO's task exports, carried as .libero_models (physics; see docs/libero_mjx.md), are copied
# to /tmp/libero_models so later calls need not carry them again; the tasks' visual files
# (meshes, textures: ~250 MB for the four suites' 40 tasks, too large for one call) come as
# xz-compressed tar parts in .vis1, .vis2, ... (benchmarks/libero_visual_parts.sh makes them)
# and are unpacked into its files/ folder.
export OPENRAL_MJX_LIBERO_MODELS=${OPENRAL_MJX_LIBERO_MODELS:-/tmp/libero_models}
if [ -d .libero_models ] && [ ! -f "$OPENRAL_MJX_LIBERO_MODELS/.copied" ]; then
  mkdir -p "$OPENRAL_MJX_LIBERO_MODELS" && cp -r .libero_models/. "$OPENRAL_MJX_LIBERO_MODELS/" \
    && touch "$OPENRAL_MJX_LIBERO_MODELS/.copied"
fi
# ... or packed as .lm/models.tar.xz (benchmarks/libero_models_tar.sh: the tasks' exports with
# their files and draws, a few MB), unpacked there once per archive.
if [ -f .lm/models.tar.xz ]; then
  lm_done="$OPENRAL_MJX_LIBERO_MODELS/.lm-$(sha256sum < .lm/models.tar.xz | cut -c1-12)"
  [ -f "$lm_done" ] || { mkdir -p "$OPENRAL_MJX_LIBERO_MODELS" \
    && tar xJf .lm/models.tar.xz -C "$OPENRAL_MJX_LIBERO_MODELS" --strip-components=1 \
    && touch "$lm_done"; }
fi
for d in .vis*; do
  [ -d "$d" ] || continue
  for a in "$d"/*.tar.xz; do
    [ -f "$a" ] || continue  # a folder of raw split parts (joined by hand), not a tar
    [ -f "$OPENRAL_MJX_LIBERO_MODELS/.$(basename "$a")-done" ] && continue
    mkdir -p "$OPENRAL_MJX_LIBERO_MODELS" && tar xJf "$a" -C "$OPENRAL_MJX_LIBERO_MODELS" \
      && touch "$OPENRAL_MJX_LIBERO_MODELS/.$(basename "$a")-done"
  done
done
# MetaWorld itself (mujoco 3.3.0) for the host baseline and the mirror's assets: carry .gpumw
# (see benchmarks/metaworld_mirror.py). Its packages go to /tmp/mwsite, put first on the path
# of the system's python (numpy, scipy) by a wrapper: the worker environment's interpreter.
if [ -d .gpumw ] && [ ! -f /tmp/mwsite/.done ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/mwsite .gpumw/*.whl \
    && printf '#!/bin/sh\nexport PYTHONPATH=/tmp/mwsite${PYTHONPATH:+:$PYTHONPATH}\nexec python3 "$@"\n' \
      > /tmp/mwpython && chmod +x /tmp/mwpython && touch /tmp/mwsite/.done
fi
[ -f /tmp/mwsite/.done ] && export OPENRAL_MJX_PYTHON_METAWORLD=/tmp/mwpython
# LIBERO's workers (below) render through EGL, and the image has no libEGL.so.1 (2026-11-29):
# carry .gl, the glvnd loader's Debian packages (libegl1 libglvnd0 libopengl0 libgl1 libglx0
# libgles2, fetched with `apt-get download`), unpacked into / where NVIDIA's EGL vendor file
# already is.
if [ -d .gl ] && ! ldconfig -p | grep -q libEGL.so.1; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done && ldconfig
fi
# LIBERO itself (hf-libero 0.1.4, robosuite 1.4.0, mujoco 3.8.1; assets pruned to the four
# suites' tasks) for the `libero` host scene, in place of the lerobot-libero worker environment:
# carry .lh1, .lh2, ... (benchmarks/libero_host_parts.sh), one or more a call. Each call's parts
# wait in /tmp/lh-parts until all that MANIFEST lists are there and match, then unpack to
# /tmp/lhsite; /tmp/lhpython (python3 with /tmp/lhsite first, then the project root) becomes
# the worker environment's interpreter. LIBERO's config (default paths, assets in the pruned
# tree: no prompt, no download) is written once here by the workers' own `configure`
# (openral_mjx/benchmarks/libero/worker_env.py), before a pool of new workers would race to
# write it. LH_SITE, LH_PARTS, LH_PYTHON and LH_PY3 (the interpreter) change the paths, for a
# local check.
LH_SITE=${LH_SITE:-/tmp/lhsite} LH_PARTS=${LH_PARTS:-/tmp/lh-parts} LH_PYTHON=${LH_PYTHON:-/tmp/lhpython}
for d in .lh[0-9]*; do
  [ -d "$d" ] || continue
  mkdir -p "$LH_PARTS" && cp "$d"/* "$LH_PARTS/"
done
if [ -f "$LH_PARTS/MANIFEST" ] && [ ! -f "$LH_SITE/.done" ] \
   && (cd "$LH_PARTS" && sha256sum --status -c MANIFEST 2> /dev/null); then
  mkdir -p "$LH_SITE" && (cd "$LH_PARTS" && awk '{print $2}' MANIFEST | xargs cat) \
      | tar xJf - -C "$LH_SITE" \
    && printf '#!/bin/sh\nexport PYTHONPATH=%s${PYTHONPATH:+:$PYTHONPATH}:%s\nexec %s "$@"\n' \
      "$LH_SITE" "$PWD" "${LH_PY3:-python3}" > "$LH_PYTHON" && chmod +x "$LH_PYTHON" \
    && PYTHONPATH='' "$LH_PYTHON" -c \
      'from openral_mjx.benchmarks.libero.worker_env import configure; configure()' \
    && touch "$LH_SITE/.done"
fi
[ -f "$LH_SITE/.done" ] && export OPENRAL_MJX_PYTHON_LEROBOT_LIBERO=$LH_PYTHON
set +e
