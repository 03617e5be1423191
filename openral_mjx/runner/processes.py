"""Several processes on one host, each driving its share of the GPUs, as one JAX job.

`launch` starts N copies of a command, process i seeing GPU group i (`CUDA_VISIBLE_DEVICES`),
and each calls `initialize` first thing: `jax.distributed.initialize` against a coordinator on
localhost, after which `jax.devices()` spans every process's devices and the runner's mesh
shards seeds over all of them (each process feeds and runs its own devices; results are
gathered to every process). Process 0 alone prints and writes reports.

Why: on `warp` one process drives two GPUs at ~1.5x one GPU (Warp launches its kernels from
Python callbacks, which take turns under the interpreter lock), while one process per GPU
reaches 2.0x. The same path is what several hosts use: there a cluster's launcher (`srun`,
`mpirun`) starts the processes, and `initialize("auto")` joins them through JAX's own
detection of the launcher's environment (or through the three variables below, set by hand).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from openral_mjx.core.errors import ConfigError

COORDINATOR = "OPENRAL_MJX_COORDINATOR"  # host:port of process 0's coordination service
NUM_PROCESSES = "OPENRAL_MJX_NUM_PROCESSES"
PROCESS_ID = "OPENRAL_MJX_PROCESS_ID"

# What JAX's detection (`jax._src.clusters`) reads of the launchers it knows, for the refusal
# when none is found: every variable of one launcher must be set.
LAUNCHER_VARIABLES = {
    "Slurm's srun": (
        "SLURM_JOB_ID",
        "SLURM_STEP_NODELIST",
        "SLURM_NTASKS",
        "SLURM_PROCID",
        "SLURM_LOCALID",
    ),
    "Open MPI's mpirun": ("OMPI_MCA_orte_hnp_uri",),
    "by hand": (COORDINATOR, NUM_PROCESSES, PROCESS_ID),
}

_joined: int | None = None  # this process's index in a job it joined from a cluster's launcher


def rank() -> int | None:
    """This process's index in its job: one `launch` started, or one a cluster's launcher started
    and `initialize("auto")` joined (None outside a job)."""
    value = os.environ.get(PROCESS_ID)
    return _joined if value is None else int(value)


def is_primary() -> bool:
    """True in process 0 (and outside a launched job): the one that prints and writes."""
    return not rank()


def launcher() -> str | None:
    """The cluster launcher whose environment this process runs in, as JAX's detection names it
    (`slurm`, `ompi`, ...), `env` for the three variables above, or None. Imports JAX (its
    registry of launchers has no public name) but starts no backend."""
    if all(name in os.environ for name in (COORDINATOR, NUM_PROCESSES, PROCESS_ID)):
        return "env"
    from jax._src import clusters

    for env in clusters.ClusterEnv._cluster_types:
        if not env.opt_in_only_method and env.is_env_present():
            return env.name
    return None


def check_launcher() -> str:
    """The launcher found (see `launcher`); a one-line `ConfigError` naming the variables looked
    for where there is none."""
    found = launcher()
    if found is None:
        looked = "; ".join(f"{who}: {', '.join(v)}" for who, v in LAUNCHER_VARIABLES.items())
        raise ConfigError(
            "--distributed auto joins a job that a cluster's launcher started, but this process "
            f"has no launcher's environment (looked for {looked}); start it with srun or mpirun, "
            "or use --processes N on one host"
        )
    return found


def initialize(distributed: str | None = None) -> None:
    """Join this process's job: one `launch` started (its variables set), or with
    `distributed="auto"` one a cluster's launcher started, through `jax.distributed.initialize`'s
    own detection (Slurm, Open MPI, ...); a no-op otherwise. Call before anything uses JAX's
    devices: the distributed runtime must come up before the backends do."""
    global _joined
    if os.environ.get(PROCESS_ID) is None and distributed is None:
        return
    found = check_launcher() if os.environ.get(PROCESS_ID) is None else "env"
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")  # for CPU-only jobs
    if found == "env":
        jax.distributed.initialize(
            coordinator_address=os.environ[COORDINATOR],
            num_processes=int(os.environ[NUM_PROCESSES]),
            process_id=int(os.environ[PROCESS_ID]),
        )
        return
    # Coordinator (the launcher's first host), process count and index come from the launcher's
    # variables; on GPUs JAX gives each process the GPU of its local rank unless
    # JAX_LOCAL_DEVICE_IDS says otherwise (one process per GPU: the layout warp scales with).
    jax.distributed.initialize()
    _joined = jax.process_index()


def finish() -> None:
    """Leave the job together (no-op outside one): every process waits for the others to get
    here, then disconnects, so none finds its peers gone and logs an RPC error on the way out."""
    if rank() is None:
        return
    import jax
    from jax.experimental import multihost_utils

    multihost_utils.sync_global_devices("openral_mjx: done")
    jax.distributed.shutdown()


def visible_gpus() -> list[str]:
    """The CUDA GPUs this process may use, by `CUDA_VISIBLE_DEVICES` entry or index, found
    without starting CUDA (which would claim GPU memory in a process that only launches)."""
    listed = os.environ.get("CUDA_VISIBLE_DEVICES")
    if listed is not None:
        return [g for g in listed.split(",") if g.strip()]
    smi = shutil.which("nvidia-smi")
    if smi is None:
        return []
    try:
        lines = subprocess.run([smi, "-L"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [str(i) for i, line in enumerate(lines.splitlines()) if line.startswith("GPU ")]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def gpu_groups(n: int, gpus: list[str]) -> list[str | None]:
    """`CUDA_VISIBLE_DEVICES` of each of `n` processes: equal groups of `gpus` (None on a
    machine without GPUs: every process keeps the host's CPU devices)."""
    if not gpus:
        return [None] * n
    if len(gpus) % n:
        valid = [str(k) for k in range(1, len(gpus) + 1) if len(gpus) % k == 0]
        raise ConfigError(
            f"--processes {n} must divide the {len(gpus)} visible GPU(s) ({','.join(gpus)}); "
            f"valid: {', '.join(valid)}"
        )
    k = len(gpus) // n
    return [",".join(gpus[i * k : (i + 1) * k]) for i in range(n)]


# The most processes one command starts on this host (a job's, or a suite's tasks at once).
MAX_PROCESSES = 256


def check_count(n: int, flag: str = "--processes") -> None:
    """A job needs at least one process, and at most `MAX_PROCESSES` on one host."""
    if n < 1:
        raise ConfigError(f"{flag} must be >= 1, got {n}")
    if n > MAX_PROCESSES:
        raise ConfigError(f"{flag} must be at most {MAX_PROCESSES}, got {n}")


def launch(module: str, argv: list[str], n: int) -> int:
    """Run `python -m module argv` as `n` processes of one job; return the job's exit code.

    Process 0 keeps this terminal; the others write to log files, whose tail is printed if one
    fails. When any process fails, the rest are stopped (they would wait on it forever)."""
    check_count(n)
    groups = gpu_groups(n, visible_gpus())
    env = {**os.environ, COORDINATOR: f"127.0.0.1:{_free_port()}", NUM_PROCESSES: str(n)}
    logs = Path(tempfile.mkdtemp(prefix="openral_mjx_processes_"))
    procs: list[subprocess.Popen] = []
    with contextlib.ExitStack() as files:
        for i, gpus in enumerate(groups):
            child = {**env, PROCESS_ID: str(i)}
            if gpus is not None:
                child["CUDA_VISIBLE_DEVICES"] = gpus
            out = None if i == 0 else files.enter_context(open(logs / f"process{i}.log", "w"))
            cmd = [sys.executable, "-m", module, *argv]
            procs.append(subprocess.Popen(cmd, env=child, stdout=out, stderr=out))
        try:
            codes = _wait_all(procs)
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
    failed = [(i, c) for i, c in enumerate(codes) if c != 0]
    for i, code in failed:
        if i == 0:
            continue
        tail = (logs / f"process{i}.log").read_text(errors="replace").splitlines()[-20:]
        print(f"process {i} of {n} exited with code {code}; its log ends:", file=sys.stderr)
        print("\n".join(f"  {line}" for line in tail), file=sys.stderr)
    if not failed:
        shutil.rmtree(logs, ignore_errors=True)
    return failed[0][1] if failed else 0


def _wait_all(procs: list[subprocess.Popen]) -> list[int]:
    """Exit codes of every process; once one fails, the others get 10 s, then are stopped."""
    deadline = None
    while True:
        codes = [p.poll() for p in procs]
        if all(c is not None for c in codes):
            return [int(c) for c in codes]  # type: ignore[arg-type]
        if deadline is None and any(c not in (None, 0) for c in codes):
            deadline = time.monotonic() + 10.0
        if deadline is not None and time.monotonic() > deadline:
            for p in procs:
                if p.poll() is None:
                    p.terminate()
            return [p.wait() for p in procs]
        time.sleep(0.1)
