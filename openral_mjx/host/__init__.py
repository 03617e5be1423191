"""The host-callback adapter's machinery: simulators that cannot run in JAX live in worker
processes (`pool`, `worker`, `codec`), batched behind one callback per step (`batch`,
`gym_batch`), in worker environments of their own (`envs`); the test scene's env
(`point_reach`) and the lerobot policy server run inside those workers; a public benchmark's
worker env lives in its folder (`openral_mjx.benchmarks.<name>.worker_env`).
Modules here import nothing but this package's `core` and `host` (workers have no JAX)."""
