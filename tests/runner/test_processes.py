"""The launcher of `eval --processes N` (its job is tested end to end in test_sharding.py)."""

import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.runner import processes


def test_gpus_split_into_equal_groups():
    assert processes.gpu_groups(2, ["0", "1", "2", "3"]) == ["0,1", "2,3"]
    assert processes.gpu_groups(4, ["3", "5", "6", "7"]) == ["3", "5", "6", "7"]
    assert processes.gpu_groups(3, []) == [None, None, None]  # CPU: each keeps the host's
    with pytest.raises(ConfigError, match=r"--processes 2 must divide the 3 visible .*valid: 1, 3"):
        processes.gpu_groups(2, ["0", "1", "2"])


def test_visible_gpus_follow_cuda_visible_devices(monkeypatch):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "2,3")
    assert processes.visible_gpus() == ["2", "3"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "")
    assert processes.visible_gpus() == []


def test_a_failing_process_fails_the_job_and_shows_its_log(capsys, tmp_path):
    """Every process runs `python -m json.tool MISSING`: each exits 2; the job exits 2 and
    prints the tail of process 1's log (process 0 writes to the terminal itself)."""
    code = processes.launch("json.tool", [str(tmp_path / "missing.json")], 2)
    err = capsys.readouterr().err
    assert code == 2
    assert "process 1 of 2 exited with code 2; its log ends:" in err
    assert "missing.json" in err


def test_rank_outside_a_job(monkeypatch):
    monkeypatch.delenv(processes.PROCESS_ID, raising=False)
    assert processes.rank() is None and processes.is_primary()
    processes.initialize()  # no-op outside a job
    monkeypatch.setenv(processes.PROCESS_ID, "1")
    assert processes.rank() == 1 and not processes.is_primary()


SLURM = {
    "SLURM_JOB_ID": "4242",
    "SLURM_STEP_NODELIST": "node[001-002]",
    "SLURM_NTASKS": "2",
    "SLURM_PROCID": "1",
    "SLURM_LOCALID": "0",
}


@pytest.fixture
def no_launcher(monkeypatch: pytest.MonkeyPatch) -> pytest.MonkeyPatch:
    """An environment no launcher started (whatever this machine's own has)."""
    for names in processes.LAUNCHER_VARIABLES.values():
        for name in names:
            monkeypatch.delenv(name, raising=False)
    monkeypatch.delenv("KUBERNETES_SERVICE_HOST", raising=False)
    return monkeypatch


def test_launcher_found_by_jax_detection(no_launcher):
    """Slurm's and Open MPI's variables are found by JAX's own detection; the three variables
    `launch` sets count as a launcher too (for jobs started by hand)."""
    assert processes.launcher() is None
    for name, value in SLURM.items():
        no_launcher.setenv(name, value)
    assert processes.launcher() == "slurm"
    no_launcher.delenv("SLURM_LOCALID")  # JAX needs all five
    assert processes.launcher() is None
    no_launcher.setenv("OMPI_MCA_orte_hnp_uri", "1531576320.0;tcp://10.96.0.1:34911")
    assert processes.launcher() == "ompi"
    for name, value in {
        processes.COORDINATOR: "head:1234",
        processes.NUM_PROCESSES: "2",
        processes.PROCESS_ID: "0",
    }.items():
        no_launcher.setenv(name, value)
    assert processes.launcher() == "env"


def test_no_launcher_is_refused_naming_the_variables(no_launcher):
    with pytest.raises(ConfigError) as refused:
        processes.initialize("auto")
    message = str(refused.value)
    assert "\n" not in message
    for names in processes.LAUNCHER_VARIABLES.values():
        assert all(name in message for name in names), message
    assert processes.rank() is None  # nothing joined
