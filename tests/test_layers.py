"""Import layers: a lower layer never imports an upper one, and morfic_cli's modules import no cycle.

Every ``import`` of every module counts, the ones inside functions too (:func:`imports` walks the whole tree):
an import moved into a function to dodge a cycle still names an upward edge. docs/design.md ("Module map") shows
the same order.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "morfic_cli"

#: (layer, the module prefixes in it, why it sits there), lowest first. A module belongs to the layer of its
#: longest matching prefix; it may import its own layer and the ones below.
LAYERS: list[tuple[str, tuple[str, ...], str]] = [
    (
        "base",
        (
            "morfic_cli.__init__",
            "morfic_cli.errors",
            "morfic_cli.threads",
            "morfic_cli.runs",
            "morfic_cli.quaternion",
            "morfic_cli.quaternion_torch",
            "morfic_cli.variant_names",
            "morfic_cli.config",
            "morfic_cli.validation",
            "morfic_cli.diagnostics.metrics",
        ),
        "Errors, names, typed configs and their checks, quaternions and the pure critic metrics: imported everywhere.",
    ),
    ("store", ("morfic_cli.store",), "The artifact store knows manifests and refs, never a policy, an env or a sim."),
    ("morphology", ("morfic_cli.morphology",), "Robots, descriptors and MjSpec models, built without a simulator."),
    ("sim", ("morfic_cli.sim",), "The physics backends (MuJoCo CPU, MuJoCo Warp) step a morphology's model."),
    ("envs", ("morfic_cli.envs",), "The locomotion env turns sim frames into observations, rewards and resets."),
    ("recording", ("morfic_cli.recording",), "Curves, tables, MCAP logs and videos: files from arrays and rows."),
    ("rl", ("morfic_cli.rl",), "Training with rsl-rl: checkpoints go to a sink; trained runs load from a store."),
    (
        "evaluation",
        ("morfic_cli.evaluation", "morfic_cli.export"),
        "Evaluating and exporting trained runs: rollouts, metrics, figures, policies for deployment.",
    ),
    ("diagnostics", ("morfic_cli.diagnostics",), "Critic diagnostics read rollouts of evaluated runs."),
    ("report", ("morfic_cli.report",), "The report gathers evals and diagnoses into tables and figures."),
    ("pipeline", ("morfic_cli.pipeline", "morfic_cli.benchmarks"), "Reproduce and bench chain the steps above."),
    ("cluster", ("morfic_cli.cluster",), "Ray jobs run pipeline steps on other machines."),
    ("cli", ("morfic_cli.cli", "morfic_cli.__main__"), "The commands: parse options, wire the store, print."),
]

#: Upward imports still in the code, each (importer, imported, why it is left); the test fails when one goes away,
#: so this list only shrinks.
KNOWN_UPWARD: list[tuple[str, str, str]] = [
    ("morfic_cli.validation", "morfic_cli.envs.observations", "the history-length check reads POLICY_DIM"),
    ("morfic_cli.validation", "morfic_cli.rl.variants", "the CLI's --variant checks resolve the registry"),
    ("morfic_cli.validation", "morfic_cli.rl.config", "a stored run's config is checked by rebuilding its TrainCfg"),
    ("morfic_cli.validation", "morfic_cli.store.refs", "the CLI's ref arguments are checked as ref names"),
    ("morfic_cli.validation", "morfic_cli.morphology.distance", "the CLI's --robots check parses robot lists"),
    ("morfic_cli.diagnostics.study_summary", "morfic_cli.report.stats", "the study summary uses the report's stats"),
]


def module_name(path: Path, root: Path = PACKAGE) -> str:
    """``morfic_cli/rl/runner.py`` -> ``morfic_cli.rl.runner``; a package's ``__init__`` keeps its name."""
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" and len(parts) > 2 else parts)


def imports(source: str, module: str, *, top_level_only: bool = False) -> set[str]:
    """The morfic_cli names ``source`` imports (``from a import b`` gives ``a.b``; :func:`resolve` finds the module).

    ``top_level_only``: only the module's own statements (what runs at import), not those in functions, nor
    those under ``if TYPE_CHECKING:``.
    """
    tree = ast.parse(source)
    nodes = _top_level(tree.body) if top_level_only else ast.walk(tree)
    out: set[str] = set()
    package = module if module.endswith("__init__") else module.rpartition(".")[0]
    for node in nodes:
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            out.update(f"{base}.{a.name}" for a in node.names)  # resolve(): the module, or ``base`` for a name
    return {name for name in out if name == "morfic_cli" or name.startswith("morfic_cli.")}


def _top_level(body: list[ast.stmt]):
    """The statements a module runs at import: its body and try/if blocks, but not ``if TYPE_CHECKING:``."""
    for node in body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            yield from _top_level(node.orelse)
        elif isinstance(node, (ast.If, ast.Try)):
            yield from _top_level(node.body)
            yield from _top_level(node.orelse)
            for handler in getattr(node, "handlers", []):
                yield from _top_level(handler.body)
            yield from _top_level(getattr(node, "finalbody", []))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node


def layer_of(module: str, layers=LAYERS) -> int:
    """Index in ``layers`` of the layer whose longest prefix matches ``module``."""
    best, index = -1, None
    for i, (_, prefixes, _) in enumerate(layers):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best:
                best, index = len(prefix), i
    if index is None:
        raise AssertionError(f"{module} is in no layer of tests/test_layers.py: add it to LAYERS")
    return index


def sources(root: Path = PACKAGE) -> dict[str, str]:
    """Module name -> source of every module under ``root``."""
    return {module_name(p, root): p.read_text() for p in sorted(root.rglob("*.py"))}


def known_modules(mods: dict[str, str]) -> set[str]:
    return set(mods) | {"morfic_cli.__init__"}


def resolve(name: str, mods: set[str]) -> str | None:
    """The module an imported name is (``a.b.c`` where ``c`` is a function of ``a.b``: ``a.b``)."""
    while name:
        if name in mods:
            return name
        if name == "morfic_cli":
            return "morfic_cli.__init__"
        name = name.rpartition(".")[0]
    return None


def upward_imports(mods: dict[str, str], layers=LAYERS) -> set[tuple[str, str]]:
    """(importer, imported) pairs where a module imports a module of a higher layer."""
    known = known_modules(mods)
    found = set()
    for module, source in mods.items():
        mine = layer_of(module if module != "morfic_cli" else "morfic_cli.__init__", layers)
        for name in imports(source, module):
            target = resolve(name, known)
            if target is not None and layer_of(target, layers) > mine:
                found.add((module, target))
    return found


def cycles(mods: dict[str, str], *, top_level_only: bool = True) -> list[list[str]]:
    """The import cycles among modules (Tarjan's strongly connected components), sorted.

    ``top_level_only``: count what runs at import; False: the imports inside functions too (hidden cycles).
    """
    known = known_modules(mods)
    graph = {
        m: {t for n in imports(s, m, top_level_only=top_level_only) if (t := resolve(n, known)) not in (None, m)}
        for m, s in mods.items()
    }
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


# ---------------------------------------------------------------------------- the checks
def test_lower_layers_never_import_upper_ones():
    found = upward_imports(sources())
    known = {(a, b) for a, b, _ in KNOWN_UPWARD}
    new = sorted(found - known)
    assert not new, "upward imports (move the shared piece down, or pass it in):\n" + "\n".join(
        f"  {a} ({LAYERS[layer_of(a)][0]}) imports {b} ({LAYERS[layer_of(b)][0]})" for a, b in new
    )
    gone = sorted(known - found)
    assert not gone, f"these KNOWN_UPWARD imports are gone; remove them from the list: {gone}"


def test_the_store_imports_neither_rl_nor_envs_nor_sim():
    mods = sources()
    bad = sorted(
        (m, n)
        for m, s in mods.items()
        if m.startswith("morfic_cli.store")
        for n in imports(s, m)
        if n.startswith(("morfic_cli.rl", "morfic_cli.envs", "morfic_cli.sim"))
    )
    assert bad == []


def test_no_import_cycle_between_modules():
    assert cycles(sources()) == []


#: Cycles still hidden by imports inside functions, each with why; the test fails when one changes or goes away.
KNOWN_HIDDEN_CYCLES: list[tuple[list[str], str]] = [
    (["morfic_cli.rl.config", "morfic_cli.validation"], "validation checks a TrainCfg that rl.config builds with it"),
    (
        [
            "morfic_cli.store",
            "morfic_cli.store.gc",
            "morfic_cli.store.publish",
            "morfic_cli.store.results",
            "morfic_cli.store.transfer",
        ],
        "the store's parts take a Store and the Store calls them",
    ),
]


def test_no_new_cycle_hidden_by_imports_inside_functions():
    """E.g. evaluation's protocol -> figures -> protocol, gone since their shared names live in evaluation.names."""
    assert cycles(sources(), top_level_only=False) == sorted(c for c, _ in KNOWN_HIDDEN_CYCLES)


# ---------------------------------------------------------------------------- the checks can fail
def _tree(tmp_path: Path, files: dict[str, str]) -> dict[str, str]:
    root = tmp_path / "morfic_cli"
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return sources(root)


def test_a_planted_upward_import_is_caught_even_inside_a_function(tmp_path):
    mods = _tree(
        tmp_path,
        {
            "__init__.py": "",
            "errors.py": "",
            "store/__init__.py": "",
            "rl/__init__.py": "",
            "store/transfer.py": (
                "from morfic_cli.errors import X\n\ndef f():\n    from morfic_cli.rl.variants import V\n"
            ),
            "rl/variants.py": "from morfic_cli.store import Store\n",
        },
    )
    assert upward_imports(mods) == {("morfic_cli.store.transfer", "morfic_cli.rl.variants")}
    assert upward_imports({**mods, "morfic_cli.store.transfer": "import morfic_cli.rl\n"}) == {
        ("morfic_cli.store.transfer", "morfic_cli.rl")
    }
    relative = {**mods, "morfic_cli.store.transfer": "from ..rl import variants\n"}
    assert upward_imports(relative) == {("morfic_cli.store.transfer", "morfic_cli.rl.variants")}


def test_the_real_tree_with_one_planted_import_fails_the_layer_check(tmp_path):
    mods = sources()
    mods["morfic_cli.sim.warp"] += "\n\ndef _planted():\n    from morfic_cli.envs.math import quat_rotate\n"
    assert ("morfic_cli.sim.warp", "morfic_cli.envs.math") in upward_imports(mods) - {
        (a, b) for a, b, _ in KNOWN_UPWARD
    }


def test_a_planted_cycle_is_caught_but_not_one_inside_a_function_or_type_checking(tmp_path):
    base = {"__init__.py": "", "a.py": "from morfic_cli import b\n"}
    planted = _tree(tmp_path / "1", {**base, "b.py": "import morfic_cli.a\n"})
    assert cycles(planted) == [["morfic_cli.a", "morfic_cli.b"]]
    hidden = _tree(tmp_path / "2", {**base, "b.py": "def f():\n    import morfic_cli.a\n"})
    assert cycles(hidden) == []
    assert cycles(hidden, top_level_only=False) == [["morfic_cli.a", "morfic_cli.b"]]
    typing_only = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from morfic_cli.a import A\n"
    assert cycles(_tree(tmp_path / "3", {**base, "b.py": typing_only})) == []


@pytest.mark.parametrize(
    ("module", "layer"),
    [
        ("morfic_cli.validation", "base"),
        ("morfic_cli.rl.runner", "rl"),
        ("morfic_cli.store.run_sink", "store"),
        ("morfic_cli.cli.train", "cli"),
        ("morfic_cli.evaluation.names", "evaluation"),
    ],
)
def test_a_module_takes_the_layer_of_its_longest_prefix(module, layer):
    assert LAYERS[layer_of(module)][0] == layer
