"""The runner reads an iteration's device-resident episode logs back in one transfer (issue 35)."""

import torch

from morfic_cli.rl.curve_logger import host_values


def test_values_by_hand_and_one_read(monkeypatch):
    logs = [{"a": torch.tensor(1.5), "b": 2}, {"a": torch.tensor([3.0]), "c": torch.tensor(0.25, dtype=torch.float64)}]
    calls = []
    real = torch.Tensor.tolist

    def counted(self):
        calls.append(self.shape)
        return real(self)

    def refuse(self):
        raise AssertionError("a value was read back on its own")

    monkeypatch.setattr(torch.Tensor, "tolist", counted)
    monkeypatch.setattr(torch.Tensor, "item", refuse)
    monkeypatch.setattr(torch.Tensor, "__float__", refuse)
    assert host_values(logs) == [{"a": 1.5, "b": 2.0}, {"a": 3.0, "c": 0.25}]
    assert calls == [torch.Size([3])]  # the three tensors stacked, read once


def test_no_tensors_no_read():
    assert host_values([{"x": 1}, {}]) == [{"x": 1.0}, {}]
