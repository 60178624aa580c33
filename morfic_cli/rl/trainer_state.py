"""Trainer state (optimiser, env, RNG, logger) as tensors + JSON: loading it can never run code.

A checkpoint's trainer state is a nested structure of dicts, lists, tuples, tensors, numpy arrays and
plain values. :func:`encode` splits it into two files:

- ``trainer.json``: the structure, with every tensor replaced by ``{"__tensor__": "t0"}``. Other
  markers: ``{"__tuple__": [...]}``, ``{"__ndarray__": "t1"}`` (a numpy array kept as a tensor),
  ``{"__float__": "nan"}`` (non-finite floats), ``{"__dict__": [[key, value], ...]}`` (dicts whose keys
  are not all plain strings, e.g. optimiser states keyed by parameter index).
- ``trainer-tensors.pt``: a flat ``{"t0": tensor, ...}`` dict saved with ``torch.save`` and read with
  ``torch.load(weights_only=True)``, which only rebuilds tensors and plain containers.

:func:`decode` inverts it exactly (dtypes, shapes and values), and raises :class:`MorficError` for
anything that is not such a pair, since a bundle may come from anyone.
"""

from __future__ import annotations

import io
import json
import math
import pickle
from collections.abc import Iterable
from typing import Any

import torch

from morfic_cli.errors import MorficError, printable

#: File names of the two halves in a trainer-state manifest.
JSON_FILE = "trainer.json"
TENSORS_FILE = "trainer-tensors.pt"

#: Version of the trainer.json layout.
FORMAT = 1

_MARKERS = ("__tensor__", "__ndarray__", "__tuple__", "__float__", "__dict__")


def encode(state: Any) -> dict[str, bytes]:
    """``{JSON_FILE: bytes, TENSORS_FILE: bytes}`` of a trainer-state structure.

    Raises:
        TypeError: A value that is none of the supported kinds (a bug in the caller, not user input).
    """
    tensors: dict[str, torch.Tensor] = {}

    def put(tensor: torch.Tensor) -> str:
        key = f"t{len(tensors)}"
        tensors[key] = tensor.detach().to("cpu").clone().contiguous()
        return key

    def enc(value: Any) -> Any:
        if isinstance(value, torch.Tensor):
            return {"__tensor__": put(value)}
        if value is None or isinstance(value, bool | int | str):
            return value
        if isinstance(value, float):
            return value if math.isfinite(value) else {"__float__": repr(value)}
        if isinstance(value, tuple):
            return {"__tuple__": [enc(v) for v in value]}
        if isinstance(value, list):
            return [enc(v) for v in value]
        if isinstance(value, dict):
            if all(isinstance(k, str) and k not in _MARKERS for k in value):
                return {k: enc(v) for k, v in value.items()}
            return {"__dict__": [[enc(k), enc(v)] for k, v in value.items()]}
        if type(value).__module__ == "numpy":
            if hasattr(value, "shape") and value.shape != ():
                return {"__ndarray__": put(torch.from_numpy(value.copy()))}
            return enc(value.item())
        raise TypeError(f"cannot store a {type(value).__name__} in a trainer state")

    doc = {"format": FORMAT, "state": enc(state)}
    buf = io.BytesIO()
    torch.save(tensors, buf)
    return {JSON_FILE: json.dumps(doc, sort_keys=True).encode(), TENSORS_FILE: buf.getvalue()}


def decode(json_bytes: bytes, tensor_bytes: bytes, what: str) -> Any:
    """The structure :func:`encode` was given.

    Args:
        json_bytes: The ``trainer.json`` bytes.
        tensor_bytes: The ``trainer-tensors.pt`` bytes.
        what: Names the checkpoint in error messages.

    Raises:
        MorficError: Either half is damaged or not a trainer state.
    """

    def bad(why: str) -> MorficError:
        return MorficError(
            f"the trainer state of {what} is damaged ({why}); resume from an earlier checkpoint "
            "(--resume runs/NAME@-1) or start a new run."
        )

    try:
        doc = json.loads(json_bytes)
    except (ValueError, RecursionError) as exc:
        raise bad(f"{JSON_FILE} is not JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or "state" not in doc:
        raise bad(f"{JSON_FILE} is not a format-{FORMAT} trainer state")
    tensors = load_tensors(tensor_bytes, f"{TENSORS_FILE} of {what}")
    if not (isinstance(tensors, dict) and all(isinstance(v, torch.Tensor) for v in tensors.values())):
        raise bad(f"{TENSORS_FILE} is not a dict of tensors")

    def tensor(key: Any) -> torch.Tensor:
        if not isinstance(key, str) or key not in tensors:
            raise bad(f"it names a tensor {str(key)[:20]!r} that {TENSORS_FILE} does not hold")
        return tensors[key]

    def dec(value: Any) -> Any:
        if isinstance(value, list):
            return [dec(v) for v in value]
        if not isinstance(value, dict):
            return value
        if len(value) == 1:
            ((key, inner),) = value.items()
            if key == "__tensor__":
                return tensor(inner)
            if key == "__ndarray__":
                return tensor(inner).numpy()
            if key == "__tuple__" and isinstance(inner, list):
                return tuple(dec(v) for v in inner)
            if key == "__float__" and inner in ("nan", "inf", "-inf"):
                return float(inner)
            if key == "__dict__" and isinstance(inner, list):
                if not all(isinstance(kv, list) and len(kv) == 2 for kv in inner):
                    raise bad("a __dict__ entry is not a [key, value] pair")
                try:
                    return {dec(k): dec(v) for k, v in inner}
                except TypeError:
                    raise bad("a __dict__ key is not hashable") from None
        return {k: dec(v) for k, v in value.items()}

    try:
        return dec(doc["state"])
    except RecursionError:
        raise bad(f"{JSON_FILE} is nested too deeply") from None


def load_tensors(data: bytes, what: str, map_location: str | torch.device = "cpu") -> Any:
    """``torch.load(weights_only=True)`` of ``data`` (tensors and plain containers only, never code).

    Raises:
        MorficError: The bytes are not such a file: a pickle of other objects (refused: loading it could run code)
            or a damaged file. torch's own message is not quoted (it suggests ``weights_only=False``).
    """
    try:
        return torch.load(io.BytesIO(data), map_location=map_location, weights_only=True)
    except pickle.UnpicklingError:
        raise MorficError(
            f"{printable(what)} is refused: it is a pickle of other objects than tensors, and loading "
            "it could run code. morfic loads only files of plain tensors, since a bundle may come from "
            "anyone; use a checkpoint written by `morfic train`."
        ) from None
    except Exception:  # RuntimeError, EOFError, ...: a damaged file, or none written by torch.save
        raise MorficError(
            f"{printable(what)} is not a file of plain tensors (damaged, or not written by "
            "torch.save); use a checkpoint written by `morfic train`."
        ) from None


# ---------------------------------------------------------------------------- the structure morfic train writes
#: Sections of a trainer state's ``env`` (:meth:`~morfic_cli.envs.locomotion.LocomotionEnv.state_dict`) that hold one
#: tensor row per env, and its other entries.
ENV_PER_ENV = ("tensors", "episode_sums", "obs", "params", "backend")
ENV_COUNTERS = ("common_step_counter", "nonfinite_resets", "tracking_sum", "tracking_count")

#: Most iterations a trainer state may count (``max_iterations``' bound, morfic_cli/validation.py).
MAX_ITERATION = 10**7


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _count(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= 0


def _shown(value: Any) -> str:
    if isinstance(value, torch.Tensor):
        return f"a {value.dtype} tensor of shape {tuple(value.shape)}"
    text = printable(repr(value))
    return f"{type(value).__name__} {text[:40]}{'...' if len(text) > 40 else ''}"


def trainer_state_problems(state: Any, keys: Iterable[str]) -> list[str]:
    """What in a decoded trainer state is not what ``morfic train`` writes (pure; empty when it is).

    Checked before anything is restored: the top-level ``keys``; ``iteration`` (an integer in [0,
    :data:`MAX_ITERATION`]); ``learning_rate`` (a finite number > 0); ``torch_rng`` (a 1-D uint8 tensor); ``alg``'s
    optimiser states (``state`` dict, ``param_groups`` list); ``env``'s entries, with ``num_envs`` in [1,
    :data:`~morfic_cli.validation.MAX_ENVS`] and every tensor of :data:`ENV_PER_ENV` one row per env (every
    buffer of :attr:`~morfic_cli.envs.locomotion.LocomotionEnv._TENSORS` present); ``logger``'s buffers and counters.
    """
    from morfic_cli.validation import MAX_ENVS

    if not isinstance(state, dict):
        return [f"it is {_shown(state)}, not a dict"]
    missing = sorted(set(keys) - set(state))
    if missing:
        return [f"it lacks {', '.join(missing)}"]
    problems = []
    if not (_count(state["iteration"]) and state["iteration"] <= MAX_ITERATION):
        problems.append(f"iteration is {_shown(state['iteration'])}, not an integer in [0, {MAX_ITERATION}]")
    if not (_number(state["learning_rate"]) and state["learning_rate"] > 0):
        problems.append(f"learning_rate is {_shown(state['learning_rate'])}, not a finite number > 0")
    rng = state["torch_rng"]
    if not (isinstance(rng, torch.Tensor) and rng.dtype == torch.uint8 and rng.dim() == 1):
        problems.append(f"torch_rng is {_shown(rng)}, not a 1-D uint8 tensor")
    problems += _alg_problems(state["alg"])
    problems += _env_problems(state["env"], MAX_ENVS)
    problems += _logger_problems(state["logger"])
    return problems


def _alg_problems(alg: Any) -> list[str]:
    if not isinstance(alg, dict) or "optimizer_state_dict" not in alg:
        return [f"alg is {_shown(alg)}, not a dict with optimizer_state_dict"]
    for key, opt in alg.items():
        if key.endswith("optimizer_state_dict") and not (
            isinstance(opt, dict)
            and isinstance(opt.get("state"), dict)
            and isinstance(opt.get("param_groups"), list)
            and all(isinstance(g, dict) and _number(g.get("lr")) for g in opt["param_groups"])
        ):
            return [f"alg.{printable(key)} is not an optimiser state (state, param_groups with lr)"]
    return []


def _env_problems(env: Any, max_envs: int) -> list[str]:
    from morfic_cli.envs.locomotion import MODES, LocomotionEnv

    want = {"num_envs", "mode", "counters", "command_vx", "generator", *ENV_PER_ENV}
    if not isinstance(env, dict) or not want <= set(env):
        have = sorted(str(k) for k in env) if isinstance(env, dict) else None
        return [
            f"env is {_shown(env) if have is None else f'a dict of {have}'[:200]}, not an env state with "
            f"{', '.join(sorted(want))}"
        ]
    n = env["num_envs"]
    if not (_count(n) and 1 <= n <= max_envs):
        return [f"env.num_envs is {_shown(n)}, not an integer in [1, {max_envs}]"]
    problems = []
    if env["mode"] not in MODES:
        problems.append(f"env.mode is {_shown(env['mode'])}, not one of {', '.join(MODES)}")
    counters = env["counters"]
    if not (isinstance(counters, dict) and all(_number(counters.get(k)) for k in ENV_COUNTERS)):
        problems.append(f"env.counters is {_shown(counters)}, not {', '.join(ENV_COUNTERS)} as numbers")
    vx = env["command_vx"]
    if not (isinstance(vx, list | tuple) and len(vx) == 2 and all(_number(v) for v in vx)):
        problems.append(f"env.command_vx is {_shown(vx)}, not two finite numbers")
    gen = env["generator"]
    if not (isinstance(gen, torch.Tensor) and gen.dtype == torch.uint8 and gen.dim() == 1):
        problems.append(f"env.generator is {_shown(gen)}, not a 1-D uint8 tensor")
    for section in ENV_PER_ENV:
        rows = env[section]
        if not isinstance(rows, dict):
            problems.append(f"env.{section} is {_shown(rows)}, not a dict of tensors")
            continue
        bad = next(
            (k for k, v in rows.items() if not (isinstance(v, torch.Tensor) and v.dim() >= 1 and v.shape[0] == n)), None
        )
        if bad is not None:
            problems.append(
                f"env.{section}.{printable(bad)[:40]} is {_shown(rows[bad])}, not one row per env ({n} envs)"
            )
    lacking = sorted(set(LocomotionEnv._TENSORS) - set(env["tensors"])) if isinstance(env["tensors"], dict) else []
    if lacking:
        problems.append(f"env.tensors lacks {', '.join(lacking)}")
    return problems


def _logger_problems(logger: Any) -> list[str]:
    fields = (
        "rewbuffer",
        "lenbuffer",
        "cur_reward_sum",
        "cur_episode_length",
        "tot_timesteps",
        "tot_time",
        "wall_time_s",
    )
    if not isinstance(logger, dict) or not set(fields) <= set(logger):
        return [f"logger is {_shown(logger)}, not a dict of {', '.join(fields)}"]
    ok = {
        "rewbuffer": lambda x: isinstance(x, list) and len(x) <= 100 and all(_number(v) for v in x),
        "lenbuffer": lambda x: isinstance(x, list) and len(x) <= 100 and all(_number(v) for v in x),
        "cur_reward_sum": lambda x: isinstance(x, torch.Tensor) and x.dim() == 1,
        "cur_episode_length": lambda x: isinstance(x, torch.Tensor) and x.dim() == 1,
        "tot_timesteps": _count,
        "tot_time": lambda x: _number(x) and x >= 0,
        "wall_time_s": lambda x: _number(x) and x >= 0,
    }
    return [
        f"logger.{k} is {_shown(logger[k])}, not what morfic train writes"
        for k, test in ok.items()
        if not test(logger[k])
    ]


def check_trainer_state(state: Any, what: str, keys: Iterable[str]) -> None:
    """Raise unless ``state`` is a trainer state as ``morfic train`` writes it (:func:`trainer_state_problems`).

    Raises:
        MorficError: ``Error: the trainer state of checkpoint 'runs/x' is not one morfic train writes
            (iteration is str '3', not an integer in [0, 10000000]); ...`` (every problem, ``what`` naming the run).
    """
    problems = trainer_state_problems(state, keys)
    if problems:
        raise MorficError(
            f"the trainer state of {printable(what)} is not one `morfic train` writes ("
            f"{'; '.join(problems)}), so it cannot be resumed; resume from another checkpoint "
            "(--resume runs/NAME@N) or start a new run with `morfic train`."
        )
