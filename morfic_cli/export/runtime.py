"""Serialise a policy module to ONNX or TorchScript bytes, and run those bytes again.

ONNX goes through torch's ``torch.export``-based exporter (``dynamo=True``, which needs ``onnxscript``) at
opset :data:`ONNX_OPSET` with a dynamic ``batch`` axis on every input and output; onnxruntime runs it. The
optional packages are the ``morfic[export]`` extra; :func:`require_onnx` names it when one is missing.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import logging
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from morfic_cli.errors import MorficError

FORMATS: tuple[str, ...] = ("onnx", "torchscript")
"""``--format`` values."""

MODEL_FILES: dict[str, str] = {"onnx": "policy.onnx", "torchscript": "policy.pt"}
"""Model file name per format (store artifact and ``--out`` directory); the metadata is ``policy.json``."""

ONNX_OPSET = 18
"""ONNX opset of the exported graph (>= 17: LayerNormalization; 18 is the exporter's native opset)."""

ONNX_PACKAGES: tuple[str, ...] = ("onnx", "onnxruntime", "onnxscript")

#: A loaded policy: named float32 inputs -> outputs in the metadata's order.
Runner = Callable[[dict[str, np.ndarray]], list[np.ndarray]]


def require_onnx() -> None:
    """Import-check the ONNX packages.

    Raises:
        MorficError: One is missing; the message names ``pip install 'morfic[export]'``.
    """
    missing = []
    for name in ONNX_PACKAGES:
        try:
            importlib.import_module(name)
        except ImportError:
            missing.append(name)
    if missing:
        raise MorficError(
            f"ONNX export needs {', '.join(missing)}, which {'is' if len(missing) == 1 else 'are'} "
            "not installed; install the export extra with `pip install 'morfic[export]'` "
            "(or use --to torchscript)."
        )


def onnxruntime_version() -> str:
    """``onnxruntime <version>`` (for the verification record)."""
    import onnxruntime

    return f"onnxruntime {onnxruntime.__version__}"


def to_onnx(
    module: nn.Module,
    example: tuple[torch.Tensor, ...],
    input_names: list[str],
    output_names: list[str],
    opset: int = ONNX_OPSET,
) -> bytes:
    """Export ``module`` to an ONNX model with a dynamic batch axis.

    Args:
        module: The policy (eval mode).
        example: One example input per name, batch first.
        input_names: ONNX input names, in argument order.
        output_names: ONNX output names, in return order.
        opset: ONNX opset (>= 17).

    Returns:
        The serialised ``ModelProto``.
    """
    require_onnx()
    batch = torch.export.Dim("batch", min=1)
    dynamic = {name: {0: batch} for name in input_names}
    with _quiet_exporter(), torch.no_grad():
        program = torch.onnx.export(
            module,
            example,
            None,
            dynamo=True,
            opset_version=opset,
            verbose=False,
            input_names=input_names,
            output_names=output_names,
            dynamic_shapes=dynamic,
            optimize=True,
        )
        if program is None:  # only the legacy (dynamo=False) exporter returns nothing
            raise RuntimeError("torch.onnx.export(dynamo=True) returned no ONNX program")
        with tempfile.TemporaryDirectory(prefix="morfic-onnx-") as tmp:
            path = Path(tmp) / "policy.onnx"
            program.save(str(path), external_data=False)
            return path.read_bytes()


def with_metadata(model: bytes, props: dict[str, str]) -> bytes:
    """The ONNX model ``model`` with ``props`` as its ``metadata_props`` (replacing any it had)."""
    import onnx

    proto = onnx.load_from_string(model)
    del proto.metadata_props[:]
    onnx.helper.set_model_props(proto, props)
    return proto.SerializeToString()


def read_metadata(model: bytes) -> dict[str, str]:
    """The ``metadata_props`` of ONNX model bytes as a dict."""
    import onnx

    return {p.key: p.value for p in onnx.load_from_string(model).metadata_props}


def to_torchscript(module: nn.Module) -> bytes:
    """Script ``module`` with TorchScript and return the archive bytes (``torch.jit.load`` reads them).

    torch >= 2.10 marks TorchScript deprecated (it still works and C++ stacks still load it); the warning is
    silenced here and docs/deploy.md recommends ONNX.
    """
    buf = io.BytesIO()
    with _no_jit_deprecation():
        torch.jit.save(torch.jit.script(module), buf)
    return buf.getvalue()


def load_runner(fmt: str, data: bytes) -> Runner:
    """A callable that runs serialised model bytes on named numpy inputs, on the CPU.

    Args:
        fmt: ``onnx`` (onnxruntime) or ``torchscript`` (``torch.jit.load``).
        data: The model file's bytes.

    Raises:
        MorficError: Unknown format, missing ONNX packages, or bytes that do not load.
    """
    if fmt == "onnx":
        require_onnx()
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        try:
            session = ort.InferenceSession(data, sess_options=opts, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types
            raise MorficError(f"onnxruntime cannot load the model: {exc}") from exc

        def run_onnx(inputs: dict[str, np.ndarray]) -> list[np.ndarray]:
            return list(session.run(None, {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in inputs.items()}))

        return run_onnx
    if fmt == "torchscript":
        try:
            with _no_jit_deprecation():
                scripted = torch.jit.load(io.BytesIO(data), map_location="cpu")
        except Exception as exc:  # torch raises RuntimeError and friends
            raise MorficError(f"torch.jit.load cannot load the model: {exc}") from exc
        scripted.eval()

        def run_script(inputs: dict[str, np.ndarray]) -> list[np.ndarray]:
            with torch.no_grad():
                out = scripted(*(torch.as_tensor(np.asarray(v, dtype=np.float32)) for v in inputs.values()))
            outs = out if isinstance(out, tuple | list) else (out,)
            return [o.numpy() for o in outs]

        return run_script
    raise MorficError(f"unknown export format '{fmt}'; valid formats are: {', '.join(FORMATS)}.")


@contextlib.contextmanager
def _no_jit_deprecation() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning, message=r".*torch\.jit")
        yield


@contextlib.contextmanager
def _quiet_exporter() -> Iterator[None]:
    """Silence the exporter's own chatter (deprecation warnings, 'torchvision is not installed' log lines)."""
    logger = logging.getLogger("torch.onnx")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            yield
    finally:
        logger.setLevel(level)
