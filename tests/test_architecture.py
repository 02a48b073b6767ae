"""The package's architecture: imports run one way, from higher layers to lower ones.

The import graph of every module under ``src/aiofl`` is read with :mod:`ast` (imports at
module level, inside functions and under ``TYPE_CHECKING`` alike: a lazy import that goes
back up is still a circle).  The test fails on any import cycle and on any import from a
lower layer to a higher one, per :data:`LAYERS`.  One name per concept: no two modules
(a package is a module) and no two classes under ``src/aiofl`` share a name.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterable
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "aiofl"

LAYERS: tuple[tuple[str, ...], ...] = (
    # lowest first; a module may import from its own layer (without a cycle) or below
    # the paper's pieces; atomic file output; the bounds on every input size; the disk cache;
    # single-value checks shared by the Python objects and the config schema; user text (one
    # rule where it enters, one escape per output format); one BLAS thread;
    # numba's helpers keyed by fast-math flags; the base of every TOML table's model
    (
        "aiofl.components",
        "aiofl.outputs",
        "aiofl.limits",
        "aiofl.cache",
        "aiofl.checks",
        "aiofl.text",
        "aiofl.blas_threads",
        "aiofl.numba_patches",
        "aiofl.table_model",
    ),
    ("aiofl.layout",),  # the member vocabulary: component kinds, parameter columns
    # plain descriptions of a design, a test and the model error (uncertainty)
    ("aiofl.controller", "aiofl.scenario", "aiofl.uncertainty", "aiofl.rig"),
    ("aiofl.plants",),
    # the engine, three floors: what the kernels read (the batch record, the discrete
    # coefficient rows); the kernels as written (templates); how they are built and cached
    ("aiofl.engine.batch", "aiofl.engine.discrete_rows"),
    ("aiofl.engine.kernel",),
    ("aiofl.engine.build",),
    # the engine's entry points (simulate*, ...); the measurement a user has (sensor)
    ("aiofl.engine", "aiofl.sensor"),
    ("aiofl.config",),  # TOML -> plant + scenario + controller (+ run settings)
    # the discrete controller stepped from Python, built from a design or a config: what a
    # test rig runs, what the sampled loop's analysis and the exports' checks step
    ("aiofl.discrete_controller",),
    ("aiofl.analysis",),
    # from a logged experiment to a plant, b0, rho and a delay
    ("aiofl.identification",),
    ("aiofl.export",),
    ("aiofl.tuning",),
    ("aiofl.reporting",),
    ("aiofl.design",),  # the notebook API (plant + controller + scenario -> every command)
    ("aiofl.cli", "aiofl.__main__"),
)
"""The layers, lowest first."""

FACADE = "aiofl"  # the top-level package: names imported lazily, by string, on first use
MAX_LINES = 1000
"""A module is one concept, however long that takes; this bound only catches a module that
has grown into several.  (It was 650 lines, which split concepts over files to fit: issue
37.)"""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _resolve(name: str) -> str | None:
    """The aiofl module an imported dotted name refers to (a module, or a name in one)."""
    while name:
        if name in MODULES:
            return name
        name = name.rpartition(".")[0]
    return None


def _imports(module: str) -> set[str]:
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            # ``from pkg import sub`` imports module pkg.sub; ``from pkg import name``, pkg
            names = [
                f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names
            ]
        else:
            continue
        for name in names:
            target = _resolve(name)
            if target is not None and target != module:
                found.add(target)
    return found


GRAPH = {m: _imports(m) for m in MODULES}


def _layer(module: str) -> int | None:
    for i, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return i
    return None


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_is_read() -> None:
    """The walker sees the imports it must see (a broken walker would pass everything)."""
    assert "aiofl.engine.simulation" in GRAPH["aiofl.reporting.cases"]
    assert "aiofl.plants.base" in GRAPH["aiofl.engine.simulation"] or any(
        m.startswith("aiofl.plants") for m in GRAPH["aiofl.engine.simulation"]
    )
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles() -> None:
    cycles = _cycles(GRAPH)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_every_module_has_a_layer() -> None:
    missing = [m for m in MODULES if m != FACADE and _layer(m) is None]
    assert not missing, f"add these modules to a layer in LAYERS: {missing}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m != FACADE))
def test_imports_run_downward(module: str) -> None:
    here = _layer(module)
    assert here is not None
    upward = sorted(t for t in GRAPH[module] if t != FACADE and (_layer(t) or 0) > here)
    assert not upward, f"{module} (layer {here}) imports from higher layers: {upward}"
    assert FACADE not in GRAPH[module] or module.startswith("aiofl.cli"), (
        f"{module} imports the top-level facade 'aiofl'; import from the defining module"
    )


def test_modules_are_read_in_a_sitting() -> None:
    long = {
        m: n
        for m, p in MODULES.items()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
        and not m.endswith("_generated")
    }
    assert not long, f"modules over {MAX_LINES} lines (split them along their seams): {long}"


# The names two modules, or two classes, may share ({name: [owners]}): none, one name per
# concept (engine/discrete.py is engine/discrete_rows.py and DiscreteController one class
# since the engine-house branch); the tests below fail on a stale entry.
SHARED_MODULE_NAMES: dict[str, list[str]] = {}
SHARED_CLASS_NAMES: dict[str, list[str]] = {}


def _shared(owners: Iterable[tuple[str, str]]) -> dict[str, list[str]]:
    """The names held by more than one owner, from (name, owner) pairs: {name: owners}."""
    held: dict[str, list[str]] = {}
    for name, owner in owners:
        held.setdefault(name, []).append(owner)
    return {name: sorted(who) for name, who in sorted(held.items()) if len(who) > 1}


def _classes(module: str) -> list[str]:
    """Every class a module defines, at any depth (a class inside a function too)."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    return [node.name for node in ast.walk(tree) if isinstance(node, ast.ClassDef)]


def _check_shared(what: str, shared: dict[str, list[str]], allowed: dict[str, list[str]]) -> None:
    new = {k: v for k, v in shared.items() if allowed.get(k) != v}
    assert not new, f"{what} sharing a name (rename the less precise one): {new}"
    stale = sorted(set(allowed) - set(shared))
    assert not stale, f"{what} no longer share these names: remove them from the allowed: {stale}"


def test_shared_names_are_found() -> None:
    """The check sees a shared name (a broken check would pass everything)."""
    pairs = [("errors", "a.cli.errors"), ("errors", "a.export.errors"), ("tune", "a.cli.tune")]
    assert _shared(pairs) == {"errors": ["a.cli.errors", "a.export.errors"]}
    assert "TuneProgress" in _classes("aiofl.tuning.progress")
    assert "_GreyBoxProblem" in _classes("aiofl.identification.grey_box")  # inside a function
    with pytest.raises(AssertionError, match="sharing a name"):
        _check_shared("modules", _shared(pairs), {})
    with pytest.raises(AssertionError, match="no longer share"):
        _check_shared("modules", {}, {"errors": ["a.cli.errors", "a.export.errors"]})


def test_one_module_per_name() -> None:
    """No two modules (``aiofl.export`` the package and ``aiofl.cli.export`` say) share a name;
    a command's module is ``cli/<command>_command.py``."""
    shared = _shared((m.rpartition(".")[2], m) for m in MODULES)
    _check_shared("modules", shared, SHARED_MODULE_NAMES)


def test_one_class_per_name() -> None:
    """No two classes share a name: one concept, one class; else names that say which."""
    shared = _shared((c, m) for m in MODULES for c in _classes(m))
    _check_shared("classes", shared, SHARED_CLASS_NAMES)


KERNEL = PACKAGE / "engine" / "kernel"
FILLER = re.compile(r"aiofl/engine/build/(\w+)\.py:(\w+)")


def _placeholder_blocks(tree: ast.Module, text: str) -> tuple[set[str], list[str]]:
    """The names a template module's ``# Placeholders`` blocks assign, and the blocks' text."""
    lines = text.splitlines()
    starts = [i for i, ln in enumerate(lines) if ln.startswith("# Placeholders")]
    blocks, names = [], set()
    for start in starts:
        end = next(i for i in range(start, len(lines)) if not lines[i].strip())
        blocks.append("\n".join(lines[start:end]))
        for node in tree.body:
            if isinstance(node, ast.Assign) and start < node.lineno <= end:
                for target in node.targets:
                    names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
    return names - {"PLACEHOLDERS"}, blocks


@pytest.mark.parametrize("path", sorted(KERNEL.glob("[a-z]*.py")), ids=lambda p: p.stem)
def test_a_templates_placeholders_say_what_fills_them(path: Path) -> None:
    """A template module's placeholders (the globals the compile factory binds per kernel)
    are declared in its placeholder blocks, listed in its PLACEHOLDERS (what the factory
    checks a recipe binds), each read by a template, and each block names the recipe
    function that fills them, one that exists in engine/build/."""
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    templates = [
        f
        for f in tree.body
        if isinstance(f, ast.FunctionDef) and f.name.startswith(("_tpl_", "_blk_"))
    ]
    if not templates:  # no template (views: intrinsics the recipes bind)
        assert "# Placeholders" not in text
        return
    names, blocks = _placeholder_blocks(tree, text)
    declared = next(
        (
            n.value
            for n in tree.body
            if isinstance(n, ast.Assign)
            and "PLACEHOLDERS" in {t.id for t in n.targets if isinstance(t, ast.Name)}
        ),
        None,
    )
    assert declared is not None, f"{path.name}: no PLACEHOLDERS"
    # PLACEHOLDERS = tuple("""names""".split())
    listed = set(ast.literal_eval(declared.args[0].func.value).split())
    assert blocks and listed == names, f"{path.name}: PLACEHOLDERS {listed ^ names} differ"
    read = {n.id for f in templates for n in ast.walk(f) if isinstance(n, ast.Name)}
    assert names <= read, f"{path.name}: placeholders no template reads: {names - read}"
    for block in blocks:
        fillers = FILLER.findall(block)
        assert fillers, f"{path.name}: a placeholder block names no aiofl/engine/build/X.py:fn"
        for module, function in fillers:
            build = (PACKAGE / "engine" / "build" / f"{module}.py").read_text(encoding="utf-8")
            assert f"def {function}(" in build, f"{path.name}: {module}.py has no {function}"
