"""Bad input refused before any work: config value rules and command-argument checks, in one place.

Two entry points:

- :func:`validate_train_cfg` checks a resolved training config against :data:`RULES` (keyed by the
  dotted config path that ``--set`` uses) plus a few rules that tie fields together; it is called
  where the config is resolved (:func:`morfic_cli.rl.config.apply_overrides`).
- :func:`check_args` checks a command's own arguments (store root, output paths, run names, seeds,
  env counts, commands, robot lists) at the start of the command, before anything is computed or
  stored.

Every failure is a :class:`~morfic_cli.errors.MorficError` whose message says what is wrong and
what to do, so the CLI prints ``Error: ...`` and exits 1 with the store unchanged.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from morfic_cli.errors import MorficError

#: Largest seed (seeds go to torch generators and numpy, which take unsigned 32-bit seeds everywhere).
MAX_SEED = 2**32 - 1

#: Most parallel envs one process may build (the paper trains 4096; 16x that is far beyond one machine).
MAX_ENVS = 65536

#: Memory per training env on the CPU backend (MuJoCo model + data per env, observation histories,
#: rollout storage): measured 0.69 MB/env (cpu preset, resident memory after one iteration: 193 MB
#: at 64 envs, 500 MB at 512 envs; docs/benchmarks-history.md, "Memory per env"), rounded up.
TRAIN_BYTES_PER_ENV = 720 * 1024

#: Memory per env of the env alone (``bench env``, evaluation): measured 0.36 MB/env (the same runs
#: right after building the env: 67 MB at 64 envs, 228 MB at 512), rounded up.
SIM_BYTES_PER_ENV = 384 * 1024

#: Largest |command| in m/s a forward-velocity command may ask for.
MAX_COMMAND_VX = 10.0


# ---------------------------------------------------------------------------- value rules
@dataclass(frozen=True)
class Rule:
    """A check of one config value: ``test(value)`` true when valid; ``want`` says what a valid value is."""

    test: Callable[[Any], bool]
    want: str


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False) -> Rule:
    """A finite number in [lo, hi] (open ends with ``lo_open`` / ``hi_open``)."""

    def test(x: Any) -> bool:
        if not _finite(x):
            return False
        if lo is not None and (x <= lo if lo_open else x < lo):
            return False
        return not (hi is not None and (x >= hi if hi_open else x > hi))

    left = "" if lo is None else ("(" if lo_open else "[") + f"{lo:g}"
    right = "" if hi is None else f"{hi:g}" + (")" if hi_open else "]")
    span = (
        f"in {left}, {right}"
        if lo is not None and hi is not None
        else (f"{'>' if lo_open else '>='} {lo:g}" if lo is not None else f"{'<' if hi_open else '<='} {hi:g}")
    )
    return Rule(test, f"a finite number {span}")


def integer(lo: int, hi: int) -> Rule:
    """An integer in [lo, hi]."""
    return Rule(
        lambda x: isinstance(x, int) and not isinstance(x, bool) and lo <= x <= hi, f"an integer in [{lo}, {hi}]"
    )


def one_of(*choices: str) -> Rule:
    """One of ``choices``."""
    return Rule(lambda x: x in choices, "one of " + ", ".join(choices))


def optional(rule: Rule) -> Rule:
    """``None`` or what ``rule`` accepts."""
    return Rule(lambda x: x is None or rule.test(x), f"null or {rule.want}")


def widths(x: Any) -> bool:
    """A non-empty list of 1..8 layer widths, each in [1, 16384]."""
    return isinstance(x, list | tuple) and 1 <= len(x) <= 8 and all(integer(1, 16384).test(w) for w in x)


def ordered_pair(lo: float | None = None, hi: float | None = None) -> Rule:
    """Two finite numbers a <= b, both within [lo, hi]."""
    inner = number(lo, hi)
    return Rule(
        lambda x: isinstance(x, list | tuple) and len(x) == 2 and all(inner.test(v) for v in x) and x[0] <= x[1],
        f"[a, b] with a <= b, each {inner.want[len('a finite number ') :]}",
    )


LAYERS = Rule(widths, "a list of 1 to 8 layer widths, each an integer in [1, 16384], e.g. [512,256,128]")

#: Config path -> rule. Paths are the ``--set`` keys; every float anywhere must be finite besides.
RULES: dict[str, Rule] = {
    "seed": integer(0, MAX_SEED),
    "max_iterations": integer(1, 10**7),
    "num_steps_per_env": integer(1, 10_000),
    "save_interval": integer(1, 10**7),
    "ppo.learning_rate": number(0, 1, lo_open=True),
    "ppo.schedule": one_of("adaptive", "fixed"),
    "ppo.desired_kl": number(0, lo_open=True),
    "ppo.num_learning_epochs": integer(1, 1000),
    "ppo.num_mini_batches": integer(1, 10**6),
    "ppo.clip_param": number(0, lo_open=True),
    "ppo.gamma": number(0, 1, lo_open=True),
    "ppo.lam": number(0, 1),
    "ppo.value_loss_coef": number(0),
    "ppo.entropy_coef": number(0),
    "ppo.max_grad_norm": number(0, lo_open=True),
    "ppo.adaptation_loss_coef": number(0),
    "ppo.adaptation_learning_rate": optional(number(0, 1, lo_open=True)),
    "model.actor_hidden_dims": LAYERS,
    "model.critic_hidden_dims": optional(LAYERS),
    "model.init_std": number(0, lo_open=True),
    "env.num_envs": integer(1, MAX_ENVS),
    "env.decimation": integer(1, 100),
    "env.episode_length_s": number(0, lo_open=True),
    "env.action_scale": number(0, lo_open=True),
    "env.action_clip": number(0, lo_open=True),
    "env.sim.backend": one_of("cpu", "warp", "gpu"),
    "env.sim.num_threads": integer(1, 1024),
    "env.sim.physics_dt": number(0, 0.1, lo_open=True),
    "env.commands.resample_time_s": number(0, lo_open=True),
    "env.commands.vx_init": ordered_pair(-MAX_COMMAND_VX, MAX_COMMAND_VX),
    "env.commands.vx_limit": ordered_pair(-MAX_COMMAND_VX, MAX_COMMAND_VX),
    "env.commands.vy": ordered_pair(-MAX_COMMAND_VX, MAX_COMMAND_VX),
    "env.commands.yaw_rate": ordered_pair(-20, 20),
    "env.commands.zero_fraction": number(0, 1),
    "env.commands.curriculum_step": number(0),
    "env.commands.curriculum_threshold": number(0, 1),
    "env.rand.friction": ordered_pair(0),
    "env.rand.restitution": ordered_pair(0, 1),
    "env.rand.joint_friction": ordered_pair(0),
    "env.rand.init_joint_scale": ordered_pair(0),
    "env.rand.com_offset": number(0),
    "env.rand.push_interval_s": number(0, lo_open=True),
    "env.rand.push_vel": number(0),
    "env.rand.max_latency_steps": integer(0, 100),
    "env.rand.geometry.pool_size": integer(1, 100_000),
    **{
        f"env.rand.geometry.{key}": ordered_pair(0.01, 100)
        for key in (
            "scale",
            "base_size",
            "base_density",
            "hip_pos",
            "link_length",
            "thigh_length_ratio",
            "link_radius",
            "thigh_radius_ratio",
            "link_mass",
        )
    },
    "env.rand.geometry.min_base_clearance": number(0),
    "env.obs.history_len": integer(1, 1000),
    "env.obs.clip": number(0, lo_open=True),
    "env.gait.frequency": number(0, lo_open=True),
    "env.gait.duty": number(0, 1, lo_open=True, hi_open=True),
}


def flatten(doc: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"ppo": {"gamma": 0.99}}`` -> ``{"ppo.gamma": 0.99}`` (lists and tuples stay values)."""
    out: dict[str, Any] = {}
    for key, value in doc.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, f"{path}."))
        else:
            out[path] = value
    return out


def _nonfinite(value: Any) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, list | tuple):
        return any(_nonfinite(v) for v in value)
    return False


def config_problems(values: dict[str, Any], rules: dict[str, Rule] | None = None) -> list[str]:
    """Every rule a flattened config breaks, as ``path = value: want`` lines (pure)."""
    rules = RULES if rules is None else rules
    problems = []
    for path, value in values.items():
        rule = rules.get(path)
        if rule is not None and not rule.test(value):
            problems.append(f"{path} = {_show(value)}: must be {rule.want}")
        elif rule is None and _nonfinite(value):
            problems.append(f"{path} = {_show(value)}: must be finite")
    return problems


def _show(value: Any) -> str:
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def validate_train_cfg(cfg: Any) -> None:
    """Check a resolved :class:`~morfic_cli.rl.config.TrainCfg` before anything is built.

    Raises:
        MorficError: Every broken rule, named by its ``--set`` key, plus the env-memory estimate.
    """
    import dataclasses

    values = flatten(dataclasses.asdict(cfg))
    problems = config_problems(values)
    if not problems:
        problems += _joint_problems(cfg)
        if cfg.env.sim.backend == "cpu":
            memory = memory_problem(cfg.env.num_envs, TRAIN_BYTES_PER_ENV, "env.num_envs")
            if memory:
                problems.append(memory)
    if problems:
        raise MorficError(
            "invalid training config: " + "; ".join(problems) + ". Fix the --set values "
            "(docs/training.md lists every key)."
        )


#: Most weights one network's layers may have: its input layer (``env.obs.history_len`` frames of the policy
#: observation, plus 128 for z_priv and z_m) and its hidden layers (2^26, 256 MiB in float32; the paper's largest
#: network, film-scaled's critic, has 1.4 M). A config asking for more is refused before anything is allocated.
MAX_NETWORK_WEIGHTS = 1 << 26


def network_weights(history_len: int, widths: Iterable[int]) -> int:
    """Weights of an MLP of hidden ``widths`` whose input is ``history_len`` policy frames plus 128 latent values.

    Example: ``network_weights(16, [512, 256, 128])`` = (16 x 48 + 128) x 512 + 512 x 256 + 256 x 128 = 622592.
    """
    from morfic_cli.envs.observations import POLICY_DIM

    dims = [history_len * POLICY_DIM + 128, *widths]
    return sum(a * b for a, b in zip(dims, dims[1:], strict=False))


def _joint_problems(cfg: Any) -> list[str]:
    """The rules that tie fields together: mini-batches, procedural geometry's backend, the networks' size.

    The mini-batches fit in a batch, procedural geometry runs on the cpu backend, the networks' size is bounded.
    """
    problems = []
    batch = cfg.env.num_envs * cfg.num_steps_per_env
    if cfg.ppo.num_mini_batches > batch:
        problems.append(
            f"ppo.num_mini_batches = {cfg.ppo.num_mini_batches}: must be at most the "
            f"{batch} transitions of an iteration (env.num_envs x num_steps_per_env)"
        )
    if cfg.env.rand.geometry.enabled and cfg.env.sim.backend != "cpu":
        problems.append(
            f"env.rand.geometry.enabled = true with env.sim.backend = '{cfg.env.sim.backend}': procedural "
            "geometry runs on the cpu backend only (set env.sim.backend=cpu, no --device cuda, or "
            "env.rand.geometry.enabled=false)"
        )
    for key in ("actor_hidden_dims", "critic_hidden_dims"):
        widths = getattr(cfg.model, key) or ()
        weights = network_weights(cfg.env.obs.history_len, widths)
        if weights > MAX_NETWORK_WEIGHTS:
            problems.append(
                f"model.{key} = {_show(widths)} with env.obs.history_len = {cfg.env.obs.history_len}: "
                f"{weights} weights, more than the {MAX_NETWORK_WEIGHTS} a network may have"
            )
    return problems


def stored_cfg_problem(doc: Any) -> str | None:
    """What is wrong with the training config a stored checkpoint records, or None (pure; imports no variant).

    The same rules as a training config (:data:`RULES`, finiteness, the joint rules) after the config is rebuilt
    with its types (:func:`~morfic_cli.rl.config.train_cfg_from_dict`: unknown keys, wrong types); not the memory
    estimate (a command on a stored run builds its own envs). A bundle may come from anyone, so ``store import``
    and every load of a run (:func:`check_stored_cfg`) check it before anything is built.
    """
    import dataclasses

    from morfic_cli.rl.config import train_cfg_from_dict

    if not isinstance(doc, dict):
        return f"its config is {type(doc).__name__}, not an object"
    try:
        cfg = train_cfg_from_dict(doc)
    except MorficError as exc:
        return str(exc).rstrip(".")
    except (TypeError, ValueError, AttributeError, KeyError, RecursionError) as exc:  # a type _coerce did not foresee
        return f"its config does not fit the training config's types ({type(exc).__name__})"
    problems = config_problems(flatten(dataclasses.asdict(cfg)))
    if not problems:
        problems = _joint_problems(cfg)
    return "; ".join(problems) or None


def check_stored_cfg(doc: Any, source: str) -> Any:
    """The :class:`~morfic_cli.rl.config.TrainCfg` a stored run records, checked (:func:`stored_cfg_problem`).

    ``source`` names the run (``runs/NAME``, ``runs/NAME@N`` or an id) in the message.

    Raises:
        MorficError: ``Error: run runs/x has an invalid stored config: model.actor_hidden_dims = [-5]: must be ...``.
    """
    from morfic_cli.errors import printable
    from morfic_cli.rl.config import train_cfg_from_dict

    problem = stored_cfg_problem(doc)
    if problem is not None:
        raise MorficError(
            f"run {printable(source)} has an invalid stored config: {printable(problem)}. morfic train "
            "never writes one: the run comes from a hand-made or edited bundle; drop it, or import "
            "it again from a bundle of the store that trained it."
        )
    return train_cfg_from_dict(doc)


def available_memory() -> int | None:
    """Bytes of memory this machine has available now (``MemAvailable``), or ``None`` if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def memory_problem(num_envs: int, bytes_per_env: int, what: str) -> str | None:
    """A message when ``num_envs`` envs would need more memory than is available, else ``None``."""
    need = num_envs * bytes_per_env
    have = available_memory()
    if have is None or need <= have:
        return None
    fit = max(1, have // bytes_per_env)
    return (
        f"{what} = {num_envs} needs about {need / 2**30:.1f} GiB of memory ({bytes_per_env / 2**20:.1f} MiB per "
        f"env), but {have / 2**30:.1f} GiB is available; use at most about {fit} envs here"
    )


# ---------------------------------------------------------------------------- command arguments
def check_args(
    *,
    store: Path | None = None,
    out_file: Path | None = None,
    out_dir: Path | None = None,
    name: str | None = None,
    report_name: str | None = None,
    seed: int | None = None,
    envs: int | None = None,
    env_counts: str | None = None,
    steps: int | None = None,
    command_vx: str | None = None,
    robots: str | None = None,
    reference: str | None = None,
    variants: str | None = None,
    specs: Iterable[str] | None = None,
    trust: Iterable[str] | None = None,
) -> None:
    """Check the arguments a command was given, before it does any work.

    Args:
        store: ``--store``: must be a folder, or not exist yet.
        out_file: An output file (``--out x.csv``): not an existing folder, in a folder (or a path that can
            become one).
        out_dir: An output folder (``--out DIR``): not an existing file, and no file on the way to it.
        name: ``train --name``: a valid ref name after ``runs/``.
        report_name: ``report --name``: a valid ref name after ``reports/``.
        seed: ``--seed``: in [0, :data:`MAX_SEED`].
        envs: ``--envs`` (evaluation, diagnosis): in [1, :data:`MAX_ENVS`], and fits in memory.
        env_counts: ``bench env --envs 256,1024``: each as ``envs``.
        steps: ``--steps``: in [1, 10^7].
        command_vx: ``--command-vx 2.0,2.5``: finite numbers within +-:data:`MAX_COMMAND_VX` m/s.
        robots: ``--robots``: ``all`` or a non-empty comma list of known robots.
        reference: ``--reference``: exactly one known robot.
        variants: ``reproduce --variants``: ``all`` or a non-empty comma list of known variants.
        specs: Artifact names (refs, ids): non-empty, no control characters, at most 300 characters.
        trust: ``--trust-variant``: well-formed user variant names (``module.path:Class``, an entry-point name);
            this command consents to importing them (:func:`morfic_cli.rl.variants.trust_variants`). Checked first,
            so that ``variants`` and later steps may resolve them.

    Raises:
        MorficError: The first bad argument, with what a good one looks like.
    """
    if trust:
        _trusted_list(trust)
    if store is not None:
        check_store_root(store)
    if out_file is not None:
        check_out_file(out_file)
    if out_dir is not None:
        check_out_dir(out_dir)
    if name is not None:
        _check_ref_part("--name", name, "runs/", "film-cpu-s0")
    if report_name is not None:
        _check_ref_part("--name", report_name, "reports/", "latest")
    if seed is not None and not integer(0, MAX_SEED).test(seed):
        raise MorficError(f"--seed {seed} is out of range; use an integer in [0, {MAX_SEED}].")
    if envs is not None:
        check_env_count(envs, "--envs", SIM_BYTES_PER_ENV)
    if env_counts is not None:
        for count in parse_counts(env_counts, "--envs"):
            check_env_count(count, "--envs", SIM_BYTES_PER_ENV)
    if steps is not None and not integer(1, 10**7).test(steps):
        raise MorficError(f"--steps {steps}: step counts must be positive integers, at most 10000000.")
    if command_vx is not None:
        parse_commands_vx(command_vx)
    if robots is not None:
        _robot_list(robots, "--robots")
    if reference is not None:
        names = _robot_list(reference, "--reference")
        if len(names) != 1:
            raise MorficError(
                f"--reference takes one robot, got {len(names)} ({', '.join(names)}); e.g. --reference go2."
            )
    if variants is not None:
        _variant_list(variants)
    for spec in specs or ():
        check_spec(spec)


def check_store_root(root: Path) -> None:
    """``--store`` must be a folder or not exist yet (then the first write creates it)."""
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise MorficError(
            f"--store {root} is a file, not a store folder; pass a folder (or a path that does "
            "not exist yet) to --store or MORFIC_STORE."
        )
    _no_file_on_the_way(root, "--store")


def check_out_file(path: Path) -> None:
    """An output file path: not an existing folder, and no file where a folder on its way must be."""
    path = Path(path)
    if str(path) in ("", ".") or path.is_dir():
        raise MorficError(f"--out {path} is a folder; give a file name, e.g. --out {Path(path) / 'result.csv'}.")
    _no_file_on_the_way(path.parent, "--out")


def check_out_dir(path: Path) -> None:
    """An output folder path: not an existing file, and no file on its way."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise MorficError(f"--out {path} is a file; give a folder (it is created if missing).")
    _no_file_on_the_way(path, "--out")


def _no_file_on_the_way(path: Path, flag: str) -> None:
    for parent in [path, *path.parents]:
        if parent.exists():
            if not parent.is_dir():
                raise MorficError(
                    f"{flag} {path}: {parent} is a file, so nothing can be created under it; choose another path."
                )
            return


def _check_ref_part(flag: str, value: str, prefix: str, example: str) -> None:
    from morfic_cli.store.refs import is_ref_name

    if not is_ref_name(prefix + value) or not value:
        raise MorficError(
            f"{flag} {value!r} is not a valid name: use letters, digits, '.', '_' and '-' (and '/' "
            f"between parts), no spaces, '..' or '@', e.g. {flag} {example}."
        )


def check_spec(spec: str) -> None:
    """An artifact name (ref, ``ref@N``, id or prefix): non-empty, printable, at most 300 characters."""
    if not spec.strip() or len(spec) > 300 or any(ord(c) < 32 for c in spec):
        shown = spec[:40] + ("..." if len(spec) > 40 else "")
        raise MorficError(
            f"{shown!r} is not an artifact name; give a ref (runs/film-cpu-s0), ref@N or an id (see `morfic store ls`)."
        )


def check_env_count(count: int, flag: str, bytes_per_env: int) -> None:
    """An env count in [1, :data:`MAX_ENVS`] that fits in the memory available now."""
    if not integer(1, MAX_ENVS).test(count):
        raise MorficError(f"{flag} {count}: env counts must be positive integers, at most {MAX_ENVS}.")
    problem = memory_problem(count, bytes_per_env, flag)
    if problem:
        raise MorficError(problem + ".")


def parse_counts(text: str, flag: str) -> list[int]:
    """``"256,1024"`` -> ``[256, 1024]``."""
    try:
        counts = [int(part) for part in text.split(",")]
    except ValueError:
        raise MorficError(f"{flag} takes comma-separated integers, e.g. {flag} 256,1024; got {text!r}.") from None
    return counts


def parse_commands_vx(text: str) -> list[float]:
    """``"2.0,2.5"`` -> ``[2.0, 2.5]``: finite forward commands within +-MAX_COMMAND_VX m/s."""
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        values = []
    if not values or not all(math.isfinite(v) and abs(v) <= MAX_COMMAND_VX for v in values):
        raise MorficError(
            f"--command-vx takes comma-separated finite numbers in m/s within +-{MAX_COMMAND_VX:g} "
            f"(e.g. 2.0,2.5), got {text!r}."
        )
    return values


def _robot_list(text: str, flag: str) -> list[str]:
    from morfic_cli.morphology.distance import parse_robot_list

    names = parse_robot_list(text)
    if not names:
        raise MorficError(f"{flag} is empty; give 'all' or robot names such as go1,a1 (see `morfic robots ls`).")
    return names


def _variant_list(text: str) -> list[str]:
    from morfic_cli.errors import UnknownNameError
    from morfic_cli.rl.variants import VARIANTS, is_import_path, resolve_variant, trust_variants

    if text.strip().lower() == "all":
        return list(VARIANTS)
    names = [v.strip() for v in text.split(",") if v.strip()]
    if not names:
        raise MorficError("--variants is empty; give 'all' or variants such as film,concat.")
    for name in names:
        if is_import_path(name):
            trust_variants([name])  # named on this command line: the user's consent to import it
            resolve_variant(name)  # a user's variant (module:Class): Error: when it cannot be imported
        elif name not in VARIANTS:
            raise UnknownNameError("variant", name, VARIANTS)
    return names


def _trusted_list(names: Iterable[str]) -> None:
    """``--trust-variant``: each a well-formed user variant name, consented to for this command (nothing imported)."""
    from morfic_cli.rl.variants import STOCK, check_variant_name, trust_variants

    for name in names:
        try:
            check_variant_name(name)
        except MorficError as exc:
            raise MorficError(f"--trust-variant: {exc}") from None
        if name in STOCK:
            raise MorficError(
                f"--trust-variant {name}: {name} is a stock variant, which needs no trust; give a user "
                "variant, module.path:Class or an entry-point name."
            )
    trust_variants(names)
