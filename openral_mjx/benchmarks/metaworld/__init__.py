"""MetaWorld v3: the host scene (`host_scene`, scene `metaworld`), the env its workers run
(`worker_env`), the native mirror (`mirror`, scene `metaworld_mjx`), MetaWorld's scripted
expert (`expert`, policy `metaworld-expert`), and the mirror's agreement (`agreement`) and
render (`render`) checks against MetaWorld itself.

Imports nothing: `worker_env` is imported inside the ``metaworld`` worker environment."""
