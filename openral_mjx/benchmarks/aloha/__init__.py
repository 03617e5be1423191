"""gym-aloha's bimanual ALOHA: the host scene (`host_scene`, scene `aloha`) and the env its
workers run (`worker_env`).

Imports nothing: `worker_env` is imported inside the ``gym-envs`` worker environment."""
