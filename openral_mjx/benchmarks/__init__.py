"""Public benchmarks, one folder each: a benchmark's host scene spec, its worker-side env, its
mirror scene, its expert, and its agreement and render checks live together
(docs/architecture.md, "Benchmark folders").

Each module in a folder is named for its role, and its role gives it its layer
(`tests/test_layers.py`): `host_scene`, `mirror` and `instructions` (data) are scenes,
`worker_env` is host, `expert` is policies, `render` is viz, `agreement` is evaluation. Imports
still point down.

This package and each folder's `__init__` import nothing: the worker env is imported inside
the benchmark's own worker environment, which has no JAX.
"""
