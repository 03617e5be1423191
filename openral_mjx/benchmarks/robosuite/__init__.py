"""robosuite: the host scene (`host_scene`, scene `robosuite`, and the Panda-under-OSC scene
that LIBERO's also is) and the env its workers run (`worker_env`).

Imports nothing: `worker_env` is imported inside the ``lerobot-libero`` worker environment."""
