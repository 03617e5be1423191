"""LIBERO: the host scene (`host_scene`, scene `libero`), the env its workers run
(`worker_env`), and LIBERO's task instructions (`instructions`, data). LIBERO runs on
robosuite's Panda scenes, so `host_scene` builds on `openral_mjx.benchmarks.robosuite`.

Imports nothing: `worker_env` is imported inside the ``lerobot-libero`` worker environment."""
