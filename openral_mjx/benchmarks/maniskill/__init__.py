"""ManiSkill3's table-top tasks: the host scene (`host_scene`, scene `maniskill`) and the env
its workers run (`worker_env`).

Imports nothing: `worker_env` is imported inside the ``maniskill`` worker environment."""
