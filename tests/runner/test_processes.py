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
