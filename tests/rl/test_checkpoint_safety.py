"""Checkpoints a bundle can't abuse and a kill can't break (issue 20, items 1 and 4).

- A bundle whose trainer state or weights are a pickle that runs code: `train --resume` / `eval` exit 1
  with `Error:` and the code never runs (its marker file is never created).
- A checkpoint is one ref update: a kill at every point between its writes leaves `runs/NAME` resumable.
- Trainer state round-trips through tensors + JSON exactly.
"""

from __future__ import annotations

import io
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from morfic_cli.errors import MorficError
from morfic_cli.rl import trainer_state
from morfic_cli.rl.config import smoke_preset
from morfic_cli.rl.runner import new_run, resume_run
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")


class _Payload:
    """Unpickling this creates ``marker`` (standing in for any code a crafted pickle could run)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def _evil_pickle(marker: Path) -> bytes:
    buf = io.BytesIO()
    torch.save({"alg": _Payload(marker), "actor": _Payload(marker)}, buf)
    return buf.getvalue()


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A smoke run of one iteration, trained once for the module: runs/film-s0."""
    root = tmp_path_factory.mktemp("trained") / "store"
    cfg = smoke_preset("film")
    run = new_run(Store(root), type(cfg)(**{**cfg.__dict__, "max_iterations": 1}), "film-s0")
    run.train()
    run.env.close()
    return root


def _copy(trained: Path, tmp_path: Path) -> Store:
    shutil.copytree(trained, tmp_path / "src")
    return Store(tmp_path / "src")


def _bundle_of(store: Store, refs: list[str], tmp_path: Path) -> Path:
    return store.export_tar(refs, tmp_path / "bundle.tar").path


def test_evil_pickle_payload_self_check(tmp_path):
    """The payload really runs code when unpickled the old way (so the tests below can fail)."""
    marker = tmp_path / "ran"
    torch.load(io.BytesIO(_evil_pickle(marker)), weights_only=False)
    assert marker.exists()


@pytest.mark.parametrize("layout", ["trainer state", "legacy resume/ trainer.pt", "weights"])
def test_a_pickle_payload_in_a_bundle_never_runs(trained, tmp_path, run_cli, layout):
    src = _copy(trained, tmp_path)
    marker = tmp_path / "marker"
    ckpt = src.read_manifest("runs/film-s0")
    files = {name: src.read_file(ckpt.id, name) for name in ckpt.files}
    inputs = dict(ckpt.inputs)
    refs = ["runs/evil"]
    if layout == "trainer state":
        state = src.read_manifest(inputs["trainer_state"])
        inputs["trainer_state"] = src.put_manifest(
            "checkpoint",
            config=state.config,
            meta=state.meta,
            files={"trainer.json": src.read_file(state.id, "trainer.json"), "trainer-tensors.pt": _evil_pickle(marker)},
        )
    elif layout == "legacy resume/ trainer.pt":
        inputs = {}
    else:
        files["model.pt"] = _evil_pickle(marker)
    meta = dict(ckpt.meta, run="evil")
    evil = src.put_manifest("checkpoint", config=ckpt.config, meta=meta, inputs=inputs, files=files)
    src.set_ref("runs/evil", evil)
    if layout == "legacy resume/ trainer.pt":  # the layout of runs written before the one-ref checkpoint
        src.set_ref(
            "resume/evil",
            src.put_manifest(
                "checkpoint",
                config={"role": "trainer-state"},
                inputs={"checkpoint": evil},
                files={"trainer.pt": _evil_pickle(marker)},
            ),
        )
        refs.append("resume/evil")
    bundle = _bundle_of(src, refs, tmp_path)
    dst = tmp_path / "dst"
    assert run_cli("store", "import", str(bundle), "--store", str(dst))[0] == 0
    commands = [["train", "--resume", "runs/evil", "--store", str(dst)]]
    if layout == "weights":
        commands.append(["eval", "runs/evil", "--robots", "go2", "--store", str(dst), "-q"])
    for argv in commands:
        code, _, err = run_cli(*argv)
        assert code == 1, err
        assert err.startswith("Error: ") and "Traceback" not in err
        assert "is refused: it is a pickle of other objects than tensors, and loading it could run code" in err
        assert "weights_only" not in err  # torch's own message, which suggests weights_only=False, is not quoted
        assert not marker.exists()


def test_an_exported_run_now_carries_its_trainer_state_and_resumes(trained, tmp_path, run_cli):
    src = _copy(trained, tmp_path)
    bundle = src.export_tar(["runs/film-s0"], tmp_path / "b.tar", latest=True).path
    dst = tmp_path / "dst"
    assert run_cli("store", "import", str(bundle), "--store", str(dst))[0] == 0
    code, _, err = run_cli("train", "--resume", "runs/film-s0", "--set", "max_iterations=2", "-q", "--store", str(dst))
    assert code == 0, err
    assert Store(dst).read_manifest("runs/film-s0").meta["iteration"] == 2


class _Killed(BaseException):
    """Stands in for kill -9 at a write: nothing after it in the writer runs."""


def _kill_at(monkeypatch, k: int) -> list[str]:
    """Make the k-th store write (an ``os.replace`` into place, or an index marker) raise :class:`_Killed`."""
    writes: list[str] = []
    real_replace, real_open = os.replace, os.open

    def count(what: str) -> None:
        if len(writes) == k:
            raise _Killed(what)
        writes.append(what)

    def replace(src, dst, *a, **kw):
        count(f"replace {dst}")
        return real_replace(src, dst, *a, **kw)

    def open_(path, flags, *a, **kw):
        if flags & os.O_EXCL and "manifests" in str(path):
            count(f"index {path}")
        return real_open(path, flags, *a, **kw)

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(os, "open", open_)
    return writes


def test_a_kill_at_every_point_between_the_checkpoint_writes_leaves_the_run_resumable(tmp_path, monkeypatch):
    root = tmp_path / "store"
    cfg = smoke_preset("film")
    run = new_run(Store(root), type(cfg)(**{**cfg.__dict__, "max_iterations": 1}), "k")
    run.train()  # iteration 1: checkpoint runs/k@1
    first = run.checkpoints[-1].id
    run.cfg = type(run.cfg)(**{**run.cfg.__dict__, "max_iterations": 2})
    with monkeypatch.context() as mp:  # iteration 2 without its checkpoint: that one is written below
        mp.setattr(run, "save_checkpoint", lambda **_: None)
        run.train()
    run.env.close()
    saved = tmp_path / "saved"
    shutil.copytree(root, saved)
    with monkeypatch.context() as mp:
        all_writes = _kill_at(mp, 10**9)
        run.save_checkpoint(finished=True)
    run.parent = run.head = first  # as if that save had not happened
    assert len(all_writes) >= 9  # 5 file objects, 2 manifests, 2 index markers, the ref and its head
    for k in range(len(all_writes) + 1):
        shutil.rmtree(root)
        shutil.copytree(saved, root)
        with monkeypatch.context() as mp:
            _kill_at(mp, k)
            if k < len(all_writes):
                with pytest.raises(_Killed):
                    run.save_checkpoint(finished=True)
            else:
                run.save_checkpoint(finished=True)
        store = Store(root)
        head = store.read_manifest("runs/k")
        assert head.id == first or (head.meta["iteration"] == 2 and head.meta["parent"] == first), k
        resumed = resume_run(store, "runs/k")  # never "no trainer state"
        assert resumed.iteration == head.meta["iteration"], k
        resumed.env.close()
        with pytest.raises(MorficError, match="already exists.*--resume runs/k"):
            new_run(store, cfg, "k")
        assert store.verify().ok, (k, store.verify().problems)
        run.parent = run.head = first


def test_trainer_state_round_trip_is_exact():
    state = {
        "iteration": 7,
        "learning_rate": 3e-4,
        "nan": math.nan,
        "inf": -math.inf,
        "none": None,
        "flag": True,
        "alg": {
            "optimizer_state_dict": {
                "state": {0: {"step": torch.tensor(3.0), "exp_avg": torch.randn(4, 3)}},
                "param_groups": [{"lr": 1e-3, "params": [0], "betas": (0.9, 0.999)}],
            }
        },
        "env": {
            "generator": torch.Generator().manual_seed(5).get_state(),
            "command_vx": (-1.0, 1.5),
            "counters": {"step": 2**40},
            "array": np.arange(6, dtype=np.int16).reshape(2, 3),
        },
        "rng": torch.get_rng_state(),
        "tricky": {"__tensor__": "not a marker"},
    }
    files = trainer_state.encode(state)
    assert set(files) == {"trainer.json", "trainer-tensors.pt"}
    back = trainer_state.decode(files["trainer.json"], files["trainer-tensors.pt"], "test")
    assert back["iteration"] == 7 and back["learning_rate"] == 3e-4 and back["none"] is None and back["flag"] is True
    assert math.isnan(back["nan"]) and back["inf"] == -math.inf
    opt = back["alg"]["optimizer_state_dict"]
    assert list(opt["state"]) == [0] and torch.equal(
        opt["state"][0]["exp_avg"], state["alg"]["optimizer_state_dict"]["state"][0]["exp_avg"]
    )
    assert opt["param_groups"][0]["betas"] == (0.9, 0.999)
    assert torch.equal(back["env"]["generator"], state["env"]["generator"])
    assert back["env"]["generator"].dtype == torch.uint8
    assert back["env"]["command_vx"] == (-1.0, 1.5) and back["env"]["counters"]["step"] == 2**40
    assert back["env"]["array"].dtype == np.int16 and back["env"]["array"].tolist() == [[0, 1, 2], [3, 4, 5]]
    assert torch.equal(back["rng"], state["rng"]) and back["tricky"] == {"__tensor__": "not a marker"}


@pytest.mark.parametrize(
    "json_bytes",
    [
        b"{",
        b"[]",
        b'{"format": 1, "state": {"__tensor__": "t99"}}',
        b'{"format": 1, "state": {"__dict__": [[["unhashable"], 1]]}}',
    ],
)
def test_a_damaged_trainer_state_is_an_error(json_bytes):
    tensors = trainer_state.encode({})["trainer-tensors.pt"]
    with pytest.raises(MorficError, match="trainer state of test is damaged"):
        trainer_state.decode(json_bytes, tensors, "test")


def test_a_run_in_the_old_two_ref_layout_still_resumes(trained, tmp_path):
    """Migration: runs/NAME without a trainer_state input, trainer.pt (torch.save of the state) under resume/NAME."""
    src = _copy(trained, tmp_path)
    ckpt = src.read_manifest("runs/film-s0")
    state = src.read_manifest(ckpt.inputs["trainer_state"])
    trainer = trainer_state.decode(
        src.read_file(state.id, "trainer.json"), src.read_file(state.id, "trainer-tensors.pt"), "test"
    )
    buf = io.BytesIO()
    torch.save(trainer, buf)  # exactly what morfic wrote as trainer.pt before the one-ref layout
    files = {name: src.read_file(ckpt.id, name) for name in ckpt.files}
    meta = dict(ckpt.meta, run="old")
    old = src.put_manifest("checkpoint", config=ckpt.config, meta=meta, files=files)
    src.set_ref("runs/old", old)
    src.set_ref(
        "resume/old",
        src.put_manifest(
            "checkpoint",
            config={"role": "trainer-state"},
            inputs={"checkpoint": old},
            files={"trainer.pt": buf.getvalue()},
        ),
    )
    resumed = resume_run(src, "runs/old")
    assert resumed.iteration == 1
    for key, value in resumed.runner.alg.optimizer.state_dict()["state"].items():
        assert torch.equal(value["exp_avg"], trainer["alg"]["optimizer_state_dict"]["state"][key]["exp_avg"])
    resumed.env.close()
    # the old layout's kill window: runs/old moved on, resume/old did not; the error names the way out
    src.set_ref(
        "runs/old", src.put_manifest("checkpoint", config=ckpt.config, meta=dict(meta, iteration=2), files=files)
    )
    with pytest.raises(MorficError, match=r"no trainer state.*--resume runs/old@1"):
        resume_run(src, "runs/old")
