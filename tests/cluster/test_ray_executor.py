"""``morfic reproduce --executor ray`` on a real local Ray cluster (2 CPUs) that only 127.0.0.1 can reach.

Ray resolves ``--node-ip-address 127.0.0.1`` to the machine's routable address and binds its gRPC servers to
every interface, so the cluster runs in a private network namespace (``unshare -rn``) whose only interface is
the loopback: the head, its workers and the ``morfic`` commands of these tests all live there, and nothing
outside the machine can reach them. The cluster is stopped at the end. Each test runs the smoke pipeline for two
variants (about a minute on 2 cores); they are slow tests (``-m slow``) and skip without ray or namespaces.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

pytest.importorskip("ray", reason="the Ray tests need `pip install 'morfic[cluster]'`")
from tests.cluster.store_contents import comparable, differences  # noqa: E402

pytestmark = pytest.mark.slow

PORT = 6391
ADDRESS = f"127.0.0.1:{PORT}"
ARGS = ["reproduce", "--preset", "smoke", "--variants", "film,ppo", "--format", "json"]
MORFIC = [sys.executable, "-m", "morfic_cli"]


class Cluster:
    """A namespace holder process and ``ray start --head --block`` inside it."""

    def __init__(self) -> None:
        self.tmp = Path(tempfile.mkdtemp(prefix="/tmp/mray"))  # short: Ray's unix socket paths are limited
        self.holder = subprocess.Popen(["unshare", "-rn", "sh", "-c", "ip link set lo up && exec sleep 3600"])
        time.sleep(0.5)
        if self.holder.poll() is not None:
            pytest.skip("needs network namespaces (`unshare -rn`) to keep the Ray cluster on 127.0.0.1")
        ray_bin = str(Path(sys.executable).with_name("ray"))
        self.log = open(self.tmp / "head.log", "w")  # noqa: SIM115
        self.head = subprocess.Popen(
            self.ns(
                [
                    ray_bin,
                    "start",
                    "--head",
                    "--num-cpus",
                    "2",
                    "--node-ip-address",
                    "127.0.0.1",
                    "--port",
                    str(PORT),
                    "--temp-dir",
                    str(self.tmp / "ray"),
                    "--include-dashboard=false",
                    "--disable-usage-stats",
                    "--block",
                ]
            ),
            stdout=self.log,
            stderr=subprocess.STDOUT,
            env={**os.environ, "OMP_NUM_THREADS": "1"},
        )
        deadline = time.monotonic() + 180
        while "Ray runtime started" not in (self.tmp / "head.log").read_text():
            if self.head.poll() is not None or time.monotonic() > deadline:
                self.stop()
                pytest.fail("ray start --head did not come up:\n" + (self.tmp / "head.log").read_text()[-3000:])
            time.sleep(1)

    def ns(self, args: list[str]) -> list[str]:
        """``args`` run inside the cluster's network namespace."""
        return ["nsenter", "-t", str(self.holder.pid), "-U", "-n", "--preserve-credentials", *args]

    def morfic(self, *args: str, store: Path, **kw) -> subprocess.Popen:
        return subprocess.Popen(
            self.ns([*MORFIC, *args, "--store", str(store)]),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            **kw,
        )

    def stop(self) -> None:
        """SIGTERM to ``ray start --block`` stops every process of the cluster; then the namespace."""
        if self.head.poll() is None:
            self.head.send_signal(signal.SIGTERM)
            try:
                self.head.wait(60)
            except subprocess.TimeoutExpired:
                self.head.kill()
        self.holder.kill()
        self.holder.wait()
        self.log.close()
        shutil.rmtree(self.tmp, ignore_errors=True)


@pytest.fixture(scope="module")
def cluster():
    c = Cluster()
    yield c
    c.stop()


def _run(proc: subprocess.Popen, timeout: float = 540) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


@pytest.fixture(scope="module")
def stores(cluster, tmp_path_factory):
    """The same command into empty stores with ``--executor local`` and ``--executor ray``."""
    base = tmp_path_factory.mktemp("stores")
    local, ray_store = base / "local", base / "ray"
    rc, _, err = _run(cluster.morfic(*ARGS, "-q", store=local))
    assert rc == 0, err
    rc, _, err = _run(cluster.morfic(*ARGS, "--executor", "ray", "--address", ADDRESS, store=ray_store))
    assert rc == 0, err
    return local, ray_store, err


def _verify(cluster, store: Path) -> None:
    rc, out, err = _run(cluster.morfic("store", "verify", store=store), timeout=120)
    assert rc == 0, out + err


def test_ray_store_matches_local(cluster, stores):
    local, ray_store, err = stores
    assert "on " in err and "127.0.0.1" in err  # each job says where it ran
    a, b = comparable(local), comparable(ray_store)
    assert sorted(a) == sorted(b)
    assert sorted(a) == [
        "diagnoses/calibration",
        "diagnoses/fixed-rollout/aliengo",
        "diagnoses/fixed-rollout/mini_cheetah",
        "evals/film-smoke-s0",
        "evals/ppo-smoke-s0",
        "reports/smoke",
        "runs/film-smoke-s0",
        "runs/ppo-smoke-s0",
        "tables/compare-baselines",
        "tables/morphology-support",
    ]
    assert [len(v["files"]["model.pt"]) for v in b["runs/film-smoke-s0"]] == [64, 64]  # weights by id, 2 checkpoints
    assert differences(a, b) == []
    _verify(cluster, ray_store)


def test_rerun_skips_everything(cluster, stores):
    _, ray_store, _ = stores
    rc, out, err = _run(cluster.morfic(*ARGS, "--executor", "ray", "--address", ADDRESS, store=ray_store))
    assert rc == 0, err
    import json

    doc = json.loads(out)
    assert doc["work_done"] == 0 and doc["skipped"] == 10


def _worker_pids(task: str) -> list[int]:
    ps = subprocess.run(["ps", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    return [int(line.split(None, 1)[0]) for line in ps.splitlines() if f"ray::{task}" in line]


def test_killed_worker_is_retried(cluster, stores, tmp_path):
    """SIGKILL the worker process training runs/film-smoke-s0: Ray retries it; the store matches the fault-free run."""
    _, ray_store, _ = stores
    store = tmp_path / "faulted"
    proc = cluster.morfic(*ARGS, "--executor", "ray", "--address", ADDRESS, store=store)
    deadline, killed = time.monotonic() + 300, None
    while killed is None and time.monotonic() < deadline and proc.poll() is None:
        pids = _worker_pids("morfic-train-runs-film-smoke-s0")
        if pids:
            killed = pids[0]
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.1)
    rc, _, err = _run(proc)
    assert killed is not None, "never saw the training task's worker process:\n" + err
    assert rc == 0, err
    line = next(x for x in err.splitlines() if x.startswith("train runs/film-smoke-s0"))
    assert f"pid {killed}" not in line  # it finished in another process: the retry
    _verify(cluster, store)
    assert differences(comparable(ray_store), comparable(store)) == []


def test_ctrl_c_then_rerun_skips_what_is_done(cluster, stores, tmp_path):
    _, ray_store, _ = stores
    store = tmp_path / "interrupted"
    proc = cluster.morfic(*ARGS, "--executor", "ray", "--address", ADDRESS, store=store)
    deadline = time.monotonic() + 300
    while not (store / "refs" / "evals").exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    rc, _, err = _run(proc)
    assert rc == 130, err
    assert "cancelled" in err
    _verify(cluster, store)
    done = sorted(p.name for p in (store / "refs" / "runs").iterdir())
    assert done  # both trains finished before the first eval was imported
    rc, out, err = _run(cluster.morfic(*ARGS, "--executor", "ray", "--address", ADDRESS, store=store))
    assert rc == 0, err
    for name in done:
        assert f"train runs/{name}: skipped" in err
    _verify(cluster, store)
    assert differences(comparable(ray_store), comparable(store)) == []
