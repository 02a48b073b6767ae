"""The compile factory and the on-disk caches: what a kernel's fingerprint covers, when a
cached kernel is reused, and plant files built once across processes.

Nothing here compiles a kernel except the plant-file tests, which run a 0.2-s simulation
of a 2-state plant in subprocesses (each a fresh process with its own cache folder).
"""

from __future__ import annotations

import dataclasses
import json
import os
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aiofl.cache import CacheWarning
from aiofl.engine.build import compile, controller_update, instances, plant_table
from aiofl.engine.kernel import plant_calls
from aiofl.plants import get_plant
from reachable import reachable_compiled

SRC = Path(__file__).resolve().parents[1] / "src" / "aiofl"


def _recipes() -> dict[str, compile.Recipe]:
    plant = get_plant("slfjm")
    rec = instances.recipe
    return {
        "lanes w32": rec(plant, 32),
        "lanes w1": rec(plant, 1),
        "sampled lanes w32": rec(plant, 32, sampled_data=True),
        "sampled lanes w1": rec(plant, 1, sampled_data=True),
        "scalar": rec(plant, 1, variant="scalar"),
        "sampled scalar": rec(plant, 1, sampled_data=True, variant="scalar"),
        "guarded": rec(plant, 1, variant="guarded"),
        "discrete controller": controller_update.update_recipe(),
        "model-assisted discrete controller": controller_update.update_recipe(plant),
        "plant table, lanes": plant_table.table_recipe(plant, "lanes"),
        "plant table, scalar": plant_table.table_recipe(plant, "scalar"),
    }


def _code_files(recipe: compile.Recipe) -> set[str]:
    """The aiofl source files whose code a recipe's kernel can run: its templates' and
    every compiled function's and intrinsic's reachable from its bindings and their
    globals."""
    tpls = (*recipe.templates, recipe.entry)
    templates = [tpl.function for tpl in tpls]
    spaces = [fn.__globals__ for fn in templates] + [dict(tpl.bindings) for tpl in tpls]
    found = reachable_compiled(dict(recipe.bindings), *spaces)
    funcs = [*templates, *(getattr(obj, "py_func", None) or obj._defn for obj in found)]
    return {f.__code__.co_filename for f in funcs if f.__code__.co_filename.startswith(str(SRC))}


@pytest.mark.parametrize("name", list(_recipes()))
def test_fingerprint_covers_every_source_a_kernel_runs(name):
    """The fingerprint digests ``recipe.sources``: every aiofl file whose code the kernel
    can reach must be among them, or an edit of it would load a stale kernel (the sampled
    kernel once skipped the guard and the lane kernels' list missed files)."""
    recipe = _recipes()[name]
    reached = _code_files(recipe)
    assert recipe.entry.function.__code__.co_filename in reached  # the walk sees the templates
    if not name.startswith("plant table"):  # (a table calls only the plant's functions)
        assert str(SRC / "components" / "fastmath.py") in reached  # and the components'
    plant_files = {  # covered by the plant's part of the fingerprint
        getattr(fn, "py_func", fn).__code__.co_filename
        for fn in (getattr(recipe.plant, k, None) for k in compile.PLANT_FUNCTIONS)
        if fn is not None
    }
    missing = sorted(reached - set(recipe.sources) - plant_files)
    assert not missing, f"{name}: not in the fingerprint: {missing}"
    # how numba compiles its helpers is part of every kernel's code (aiofl.numba_patches)
    assert str(SRC / "numba_patches.py") in recipe.sources


def test_editing_any_source_changes_the_fingerprint(tmp_path):
    """Each source file of each recipe, edited in a temporary copy, changes the recipe's
    fingerprint; the unedited recipe keeps it."""
    for name, recipe in _recipes().items():
        before = compile.fingerprint(recipe)
        assert before is not None and compile.fingerprint(recipe) == before
        for i, path in enumerate(recipe.sources):
            copy = tmp_path / f"{name.replace(' ', '_')}_{i}" / os.path.basename(path)
            copy.parent.mkdir()
            copy.write_text(Path(path).read_text() + "\n# an edit\n")
            sources = (*recipe.sources[:i], str(copy), *recipe.sources[i + 1 :])
            edited = dataclasses.replace(recipe, sources=sources)
            assert compile.fingerprint(edited) != before, (name, path)


def test_the_fingerprint_does_not_depend_on_the_hash_seed():
    """Two processes with different string-hash seeds give every recipe the same
    fingerprint (the fast-math flags are a set: its plain repr changed with the seed, so
    the scalar kernels and the discrete controller were compiled in every process)."""
    code = (
        "import json, test_compile as t; from aiofl.engine.build import compile as c; "
        "print(json.dumps({k: c.fingerprint(r) for k, r in t._recipes().items()}))"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), *sys.path])}
    out = []
    for seed in ("1", "2"):
        proc = subprocess.run(
            [sys.executable, "-c", code],
            env={**env, "PYTHONHASHSEED": seed},
            capture_output=True,
            text=True,
            check=True,
        )
        out.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    assert out[0] == out[1]
    assert out[0] == {k: compile.fingerprint(r) for k, r in _recipes().items()}
    assert compile._canonical_repr({"b", "a"}) == compile._canonical_repr({"a", "b"})


def test_kind_plant_and_options_are_part_of_the_fingerprint():
    recipes = _recipes()
    fps = {name: compile.fingerprint(r) for name, r in recipes.items()}
    assert len(set(fps.values())) == len(fps)  # every instance has its own
    r = recipes["lanes w32"]
    entry = dataclasses.replace(r.entry, options={**r.entry.options, "nogil": False})
    assert compile.fingerprint(dataclasses.replace(r, entry=entry)) != fps["lanes w32"]
    other = dataclasses.replace(r, plant=get_plant("pendulum"))
    assert compile.fingerprint(other) != fps["lanes w32"]


def test_every_placeholder_a_template_reads_is_bound_or_the_recipe_is_refused():
    """Every recipe binds each placeholder its templates read (the factory checks, with
    nothing compiled); one that leaves one unbound is refused naming it and its template
    (it used to compile against the module's stand-in ``None`` and fail in numba's
    typing), and so is a template instantiated on its own."""
    for recipe in _recipes().values():
        compile.build(recipe, cache=False)  # lazy: no compile
    rec = _recipes()["sampled lanes w32"]
    for name, template in (("_W", "_blk_"), ("_PFG", "_blk_plant"), ("_CTRL_STEP", "_tpl_sample")):
        space = {k: v for k, v in rec.bindings.items() if k != name}
        with pytest.raises(
            ValueError, match=rf"template {template}\w* .* placeholder\(s\) {name},"
        ):
            compile.build(dataclasses.replace(rec, bindings=space), cache=False)
    from aiofl.engine.kernel import member

    with pytest.raises(ValueError, match="_ESO_GAIN"):
        compile.instantiate(member._tpl_setup, compile.template_globals(member), "t")
    assert compile.unbound_placeholders(member._tpl_setup, vars(member)) == []


def _defined(source: str, name: str = "f", **space: object) -> object:
    """Function ``name`` of ``source`` executed with the globals ``space`` (no source file,
    as in a notebook cell)."""
    ns: dict = dict(space)
    exec(source, ns)
    return ns[name]


_F = "def f(x, p):\n    return (x[1], -K * x[0] + helper(x[0]))\n"
_HELPER = "def helper(v):\n    return 0.5 * v\n"


def test_a_plant_function_is_identified_by_its_code_and_what_it_reads():
    """The plant part of a kernel's fingerprint (aiofl.engine.build.code_fingerprint): the same
    code reading the same values is the same kernel wherever it is defined (a notebook cell
    without a source file, moved within its file); a change of its code, of a constant it
    reads, of a function it calls or of an array it reads is another kernel."""
    fp = compile.function_fingerprint
    helper = _defined(_HELPER, "helper")
    base = fp(_defined(_F, K=2.0, helper=helper))
    assert base is not None
    assert fp(_defined(_F, K=2.0, helper=helper)) == base  # defined again: the same
    assert fp(_defined("\n\n\n" + _F, K=2.0, helper=helper)) == base  # moved down 3 lines
    assert fp(_defined(_F, K=2.0, helper=helper, unused=object())) == base  # not read
    assert fp(_defined(_F, K=3.0, helper=helper)) != base  # a constant it reads
    assert fp(_defined(_F.replace("-K", "K"), K=2.0, helper=helper)) != base  # its code
    other = _defined(_HELPER.replace("0.5", "0.25"), "helper")
    assert fp(_defined(_F, K=2.0, helper=other)) != base  # a function it calls
    table = "def f(x, p):\n    return (x[1], T[0] * x[0])\n"
    arrays = [fp(_defined(table, T=np.array([v, 1.0]))) for v in (1.0, 1.0, 2.0)]
    assert arrays[0] == arrays[1] != arrays[2] and None not in arrays
    # a global or a closure the fingerprint cannot describe: no fingerprint
    assert fp(_defined(table, T={0: 1.0})) is None
    assert (
        fp(
            _defined(
                "def g():\n    d = {}\n    def f(x, p):\n        return d\n    return f", "g"
            )()
        )
        is None
    )


def test_a_plant_defined_in_a_notebook_cell_is_cached(tmp_path, monkeypatch):
    """A plant whose functions have no source file (``exec``, a notebook cell) has a
    kernel fingerprint and is cached; one reading a value the fingerprint cannot describe
    is compiled uncached."""
    from aiofl.plants.base import Plant

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    slfjm = get_plant("slfjm")
    f = _defined("def f(x, p):\n    return (x[1], -x[0])\n")
    plant = Plant("nofile", 2, f, slfjm.g, slfjm.h, {"a": 1.0})
    recipe = dataclasses.replace(_recipes()["lanes w32"], plant=plant)
    assert compile.fingerprint(recipe) is not None
    assert compile.build(recipe).cached
    odd = _defined("def f(x, p):\n    return (x[1], -D[0] * x[0])\n", D={0: 1.0})
    recipe = dataclasses.replace(recipe, plant=Plant("odd", 2, odd, slfjm.g, slfjm.h, {}))
    assert compile.fingerprint(recipe) is None
    assert not compile.build(recipe).cached


def test_editing_a_script_elsewhere_keeps_its_plants_kernel(tmp_path):
    """A plant defined in a script: editing the script's controller gains leaves the
    plant's fingerprint (its kernel is reused); editing the plant's code changes it."""
    script = tmp_path / "design.py"
    text = (
        "OMEGA0 = 40.0\n"
        "def f(x, p):\n    return (x[1], -p[0] * x[0])\n"
        "def use():\n    return OMEGA0\n"
    )
    prints = []
    for edit in (text, text.replace("40.0", "80.0"), text.replace("-p[0]", "-2.0 * p[0]")):
        script.write_text(edit)
        prints.append(compile.function_fingerprint(runpy.run_path(str(script))["f"]))
    assert prints[0] == prints[1] != prints[2] and None not in prints


def test_a_source_edited_after_loading_is_not_cached(tmp_path, monkeypatch):
    """The fingerprint describes the text this process first read, numba compiles the
    code it loaded: when another process edits a source in between, the kernel is built
    uncached rather than stored under either fingerprint."""
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    src = tmp_path / "tpl.py"
    src.write_text("x = 1\n")
    recipe = dataclasses.replace(_recipes()["lanes w1"], sources=(str(src),))
    assert not compile.sources_changed(recipe.sources)
    assert compile.build(recipe).cached
    src.write_text("x = 2\n")
    assert compile.sources_changed(recipe.sources)
    assert not compile.build(recipe).cached


def test_cache_folder_environment(tmp_path, monkeypatch):
    from aiofl import cache

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "c"))
    assert cache.subdir("kernels") == tmp_path / "c" / "kernels"
    recipe = _recipes()["lanes w1"]
    inst = compile.build(recipe)
    assert inst.cached and inst.entry._cache.cache_path == str(tmp_path / "c" / "kernels")
    monkeypatch.setenv("AIOFL_NO_CACHE", "1")
    assert cache.cache_root() is None and not compile.build(recipe).cached
    monkeypatch.delenv("AIOFL_NO_CACHE")
    monkeypatch.delenv("AIOFL_CACHE_DIR")
    assert cache.cache_root() is not None and cache.cache_root().name == "aiofl"


def test_entries_of_an_older_fingerprint_are_pruned(tmp_path, monkeypatch):
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path))
    recipe = _recipes()["lanes w32"]
    key = compile.plant_key(recipe.plant)
    folder = tmp_path / "kernels"
    folder.mkdir()
    stale = folder / f"loop._tpl_loop_lc32_{key}_0123456789abcdef0123-k.py311.nbi"
    other_kind = folder / f"loop._tpl_loop_ls32_{key}_0123456789abcdef0123-k.py311.nbi"
    other_plant = folder / "loop._tpl_loop_lc32_ffffffff_0123456789abcdef0123-k.py311.nbi"
    independent = folder / "loop._tpl_loop_sc1n4_noplant_0123456789abcdef0123-k.py311.nbi"
    for p in (stale, other_kind, other_plant, independent):
        p.write_bytes(b"")
    compile.build(recipe)
    assert not stale.exists() and other_kind.exists() and other_plant.exists()
    assert independent.exists()
    # a plant-independent instance prunes its own kind's older entries only
    compile.build(_recipes()["scalar"])
    assert not independent.exists() and other_kind.exists() and other_plant.exists()


def test_width_one_instances_are_plant_independent():
    """Every width-1 instance but the diagnostic one is compiled without the plant (the
    recipe has none, its kind names the number of states): one fingerprint for two plants
    of the same size, aiofl's own or a user's, another for another size.  The lane
    instances of width 32 and the diagnostic instance keep the plant; a plant's own
    compiled code is its table."""
    from aiofl.plants.base import Plant

    slfjm, pendulum = get_plant("slfjm"), get_plant("pendulum")
    user4 = Plant("user4", 4, _defined(_F4), slfjm.g, slfjm.h, dict(slfjm.params))
    user2 = Plant("user2", 2, _defined(_F2), pendulum.g, pendulum.h, {"a": 1.0})
    for variant in ("lanes", "scalar"):
        for sampled_data in (False, True):
            a, b, c = (
                instances.recipe(p, 1, sampled_data=sampled_data, variant=variant)
                for p in (user4, slfjm, user2)
            )
            assert a.plant is None and a.kind.endswith("n4") and c.kind.endswith("n2")
            assert compile.fingerprint(a) == compile.fingerprint(b) != compile.fingerprint(c)
    for width, variant in ((32, "lanes"), (1, "guarded")):
        assert instances.recipe(user4, width, variant=variant).plant is user4
    tables = [plant_table.table_recipe(p, "lanes") for p in (user4, slfjm, pendulum)]
    assert len({compile.fingerprint(t) for t in tables}) == 3


_F4 = "def f(x, p):\n    return (x[2], x[3], -p[0] * x[1], p[0] * x[1])\n"
_F2 = "def f(x, p):\n    return (x[1], -p[0] * x[0])\n"


# ------------------------------------------------------------------ plant files, cached
PLANT_TOML = """\
name = "duffing"
states = ["x", "v"]
f = ["v", "(-k*x - 0.5*k*x**3 - c*v)/m"]
g = ["0", "1/m"]
h = "x"
[params]
k = 4.0
c = 0.3
m = 1.0
"""

CONFIG_TOML = """\
plant = "duffing.toml"
[scenario]
t_final = 0.2
[scenario.reference]
kind = "step"
amplitude = 1.0
[controller]
structure = "LADRC"
[controller.eso]
omega0 = 40.0
[controller.sef]
omega_c = 5.0
[controller.td]
omega = 10.0
[controller.law]
b0 = 1.0
[simulation]
dt = 1e-3
"""

_PROBE = """\
import json, sys
from aiofl.config import load_config
from aiofl.engine.build import instances, plant_table
cfg = load_config(sys.argv[1])
res = cfg.simulate(store=False)
kernel = instances.instance_for(cfg.plant, 1).entry
entries = plant_table.table_entries(cfg.plant, "lanes")
print(json.dumps({
    "itae": res.metrics["itae"],
    "sympy": "sympy" in sys.modules,
    "compiled": [str(s) for s in kernel.signatures],
    "hits": sum(kernel.stats.cache_hits.values()),
    "misses": sum(kernel.stats.cache_misses.values()),
    "entry_hits": sum(sum(e.stats.cache_hits.values()) for e in entries),
    "entry_misses": sum(sum(e.stats.cache_misses.values()) for e in entries),
}))
"""


def _start_probe(cfg: Path, cache_dir: Path) -> subprocess.Popen:
    env = {**os.environ, "AIOFL_CACHE_DIR": str(cache_dir)}
    env.pop("AIOFL_NO_CACHE", None)
    return subprocess.Popen(
        [sys.executable, "-c", _PROBE, str(cfg)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _result(proc: subprocess.Popen) -> dict:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err[-2000:]
    return json.loads(out.strip().splitlines()[-1])


def _probe(cfg: Path, cache_dir: Path) -> dict:
    return _result(_start_probe(cfg, cache_dir))


@pytest.mark.slow
def test_a_plant_file_is_built_and_compiled_once_across_processes(tmp_path, monkeypatch):
    """Two processes on an empty cache: the plant module is written, the kernel compiled
    once and stored (the other processes wait for it and load it: the two commands and the
    processes they start to compile the 2-state loops ahead, whichever comes first).
    A third process: the plant comes from the module (no sympy import) and the kernel from
    the disk cache (a hit, no compile); same numbers.  Editing a parameter value of the
    plant file makes a new plant module (the old one pruned) but keeps the kernel: a fourth
    process loads it (the functions' module keeps its name) and runs the new value.
    Editing the model itself makes new table entries (the plant's compiled code); the time
    loop, compiled without the plant, is the one every 2-state plant runs."""
    (tmp_path / "duffing.toml").write_text(PLANT_TOML)
    cfg = tmp_path / "sim.toml"
    cfg.write_text(CONFIG_TOML)
    cache_dir = tmp_path / "cache"
    # two processes at once on an empty cache: one compiles (or a process one of them
    # started ahead, aiofl.engine.build.prepare), the others wait for it
    # (compile.compile_lock) and load the kernel it stored
    both = [_result(p) for p in [_start_probe(cfg, cache_dir), _start_probe(cfg, cache_dir)]]
    assert all(r["misses"] + r["hits"] == 1 for r in both)
    assert sum(r["misses"] for r in both) <= 1
    stored = list((cache_dir / "kernels").glob("loop._tpl_loop_lc1n2_noplant_*.nbi"))
    assert len(stored) == 1
    # the plant's table entries: each compiled once, by either process
    n_table = plant_calls.N_TABLE
    assert sum(r["entry_misses"] for r in both) == n_table
    assert all(r["entry_misses"] + r["entry_hits"] == n_table for r in both)
    first = both[0]
    assert both[1]["itae"] == first["itae"]
    modules = sorted((cache_dir / "plants").glob("plant_*.py"))
    assert len(modules) == 1
    second = _probe(cfg, cache_dir)
    assert not second["sympy"], "a cached plant file must not need sympy"
    assert second["hits"] == 1 and second["misses"] == 0
    assert (second["entry_hits"], second["entry_misses"]) == (n_table, 0)
    assert second["itae"] == first["itae"]
    # a parameter value edited: a new module, the old one pruned, the same kernel
    (tmp_path / "duffing.toml").write_text(PLANT_TOML.replace("k = 4.0", "k = 5.0"))
    stiffer = _probe(cfg, cache_dir)
    assert stiffer["hits"] == 1 and stiffer["misses"] == 0
    assert (stiffer["entry_hits"], stiffer["entry_misses"]) == (n_table, 0)
    assert stiffer["itae"] != first["itae"]
    now = sorted((cache_dir / "plants").glob("plant_*.py"))
    assert len(now) == 1 and now != modules
    # the model edited: another kernel (its fingerprint; compiled on its first run)
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(cache_dir))
    from aiofl.plants import plant_cache

    before = plant_cache.plant_from_file(tmp_path / "duffing.toml")
    entries = compile.fingerprint(plant_table.table_recipe(before, "lanes"))
    loop = compile.fingerprint(instances.recipe(before, 1))
    (tmp_path / "duffing.toml").write_text(PLANT_TOML.replace("0.5*k*x**3", "0.4*k*x**3"))
    edited = plant_cache.plant_from_file(tmp_path / "duffing.toml")
    assert compile.fingerprint(plant_table.table_recipe(edited, "lanes")) not in (None, entries)
    assert compile.fingerprint(instances.recipe(edited, 1)) == loop


def test_a_damaged_plant_module_is_rebuilt(tmp_path, monkeypatch):
    from aiofl.plants import plant_cache

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "duffing.toml"
    path.write_text(PLANT_TOML)
    plant = plant_cache.plant_from_file(path)
    module = plant_cache.plant_module_path(path)
    assert module is not None and module.is_file()
    assert plant.f.__code__.co_filename == str(module)  # a real source file
    assert plant.relative_degree == 2 and dict(plant.params) == {"k": 4.0, "c": 0.3, "m": 1.0}
    text = module.read_text()
    module.write_text(text[: len(text) // 2])  # a partial write
    with pytest.warns(CacheWarning, match="damaged"):  # more cases: test_cache_damage.py
        again = plant_cache.plant_from_file(path)
    assert module.read_text() == text
    x, p = [0.3, -0.2], [4.0, 0.3, 1.0]
    assert again.f(x, p) == plant.f(x, p)
    monkeypatch.setenv("AIOFL_NO_CACHE", "1")
    assert plant_cache.plant_module_path(path) is None
    assert plant_cache.plant_from_file(path).f(x, p) == plant.f(x, p)


_SYMBOLIC = (
    "from aiofl.plants.symbolic import SymbolicPlant\n"
    "sym = SymbolicPlant.from_strings('dbl_sym', ['x1', 'x2'], {'k': K}, "
    "['x2', 'F'], ['0', '1'], 'x1')\n"
    "plant = sym.to_plant()\n"
)


def _symbolic_kernel_identity(cache_dir: Path, k: float, f2: str = "-k*sin(x1)") -> dict:
    """In a new process: where the functions of a symbolic plant built in Python live,
    and the fingerprint of its compiled code, its table's entries (nothing is compiled)."""
    code = (
        _SYMBOLIC.replace("K", repr(k)).replace("F", f2)
        + "import json\nfrom aiofl.engine.build import compile, plant_table\n"
        + "print(json.dumps({'file': plant.f.__code__.co_filename, "
        + "'analysed': 'analysis' in sym._cache, "
        + "'fp': compile.fingerprint(plant_table.table_recipe(plant, 'lanes'))}))\n"
    )
    env = {**os.environ, "AIOFL_CACHE_DIR": str(cache_dir)}
    env.pop("AIOFL_NO_CACHE", None)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_symbolic_plant_built_in_python_gets_a_cacheable_kernel(tmp_path, monkeypatch):
    """``SymbolicPlant.to_plant()`` imports its generated functions from a module written
    into the cache: a real source file, the same module and kernel fingerprint in every
    process for the same model, and a later process takes the plant from the module
    without the symbolic analysis; another parameter value is another module but the same
    kernel (parameters reach it at run time), another model another kernel; with the
    cache off, the functions stay in memory (no file)."""
    cache_dir = tmp_path / "cache"
    first, again = (_symbolic_kernel_identity(cache_dir, 2.0) for _ in range(2))
    assert first["analysed"] and not again["analysed"]
    assert first["fp"] is not None and {**first, "analysed": 0} == {**again, "analysed": 0}
    assert Path(first["file"]).parent == cache_dir / "plants"
    stiffer = _symbolic_kernel_identity(cache_dir, 3.0)
    assert stiffer["fp"] == first["fp"] and stiffer["file"] != first["file"]
    other = _symbolic_kernel_identity(cache_dir, 2.0, "-k*x1")
    assert other["fp"] not in (None, first["fp"]) and other["file"] != first["file"]
    monkeypatch.setenv("AIOFL_NO_CACHE", "1")
    space: dict = {}
    exec(_SYMBOLIC.replace("K", "2.0").replace("F", "-k*sin(x1)"), space)
    plant = space["plant"]
    assert not os.path.isfile(plant.f.__code__.co_filename)


def test_numba_inlining_copies_a_callee_with_one_memo():
    """The compile-time fix of :func:`aiofl.engine.build.compile.share_scope_when_inlining` is in
    place on the numba version the project pins (a numba whose source changed would leave
    it out silently, and every lane instance would compile ~1.5x slower: this says so)."""
    from numba.core import inline_closurecall as ic

    assert compile.share_scope_when_inlining()
    nested = [c for c in ic.InlineWorker.inline_ir.__code__.co_consts if hasattr(c, "co_name")]
    copy_ir = next(c for c in nested if c.co_name == "copy_ir")
    assert "memo" in copy_ir.co_varnames


def test_the_probe_batch_compiles_the_signature_of_real_batches():
    """The background compile (aiofl.engine.build.prepare) is useful only if its probe batch has
    the numba types of the batches simulate_batch packs, continuous and sampled alike."""
    import numba

    from aiofl.config import load_config
    from aiofl.controller import controller_batch
    from aiofl.engine.build import prepare
    from aiofl.engine.discrete_rows import Sampling, sampling_rows
    from aiofl.engine.simulation import pack

    cfg = load_config("frontier-s1-ladrc")
    groups, batch, out = prepare.probe(cfg.plant)
    packed = controller_batch([cfg.controller] * 3)
    for disc in (None, sampling_rows(packed, [Sampling(1e-3)] * 3, cfg.dt)):
        for store in (False, True):
            rec, res = pack(
                cfg.plant,
                packed,
                [cfg.scenario] * 3,
                disc,
                dt=cfg.dt,
                method="rk4",
                store=store,
                decimation=10,
                divergence_threshold=1e10,
            )
            assert numba.typeof(rec) == numba.typeof(batch)
            assert numba.typeof(res) == numba.typeof(out)
    assert numba.typeof(groups) == numba.typeof(np.zeros((2, 32), dtype=np.int64))


def test_prepare_specs_and_a_disabled_cache(monkeypatch):
    from aiofl.engine.build import prepare

    assert prepare.parse_spec("c32") == (32, False) and prepare.parse_spec("s1") == (1, True)
    for bad in ("x1", "c", "c7", "s-1"):
        with pytest.raises(ValueError, match="allowed"):
            prepare.parse_spec(bad)
    assert prepare.main(["slfjm", "c9"]) == 2
    assert prepare.main(["slfjm", "dc", "c9"]) == 2  # refused before anything compiles
    monkeypatch.setenv("AIOFL_NO_CACHE", "1")
    assert prepare.prepare_in_background("slfjm", [(32, False)]) is None
    assert prepare.prepare_in_background("slfjm", [], controller=True) is None


def test_the_prepared_discrete_controller_is_the_one_a_command_loads(tmp_path, monkeypatch):
    """``python -m aiofl.engine.build.prepare slfjm dc`` fills the cache with the discrete
    controller's entries; a later process building a DiscreteController (another design,
    the same plant-free update) loads every entry it calls and compiles none."""
    monkeypatch.delenv("AIOFL_NO_CACHE", raising=False)
    env = {**os.environ, "AIOFL_CACHE_DIR": str(tmp_path)}
    cmd = [sys.executable, "-m", "aiofl.engine.build.prepare", "slfjm", "dc"]
    subprocess.run(cmd, env=env, check=True, capture_output=True)
    names = sorted(p.name.split("_standalone")[0] for p in (tmp_path / "kernels").glob("*.nbi"))
    assert names == [
        "member._tpl_setup",
        "sampled._tpl_ctrl_init",
        "sampled._tpl_ctrl_run",
        "sampled._tpl_ctrl_step",
        "sampled._tpl_ctrl_step_each",
    ]
    probe = (
        "import numpy as np\n"
        "from aiofl.config import load_config\n"
        "from aiofl.engine.discrete_rows import Sampling\n"
        "from aiofl.discrete_controller import DiscreteController\n"
        "dc = DiscreteController(load_config('retuned-s1-leso').controller, Sampling(1e-3))\n"
        "dc.init(0.1); dc.step([0.2, 0.0], 0.1); dc.run(3, 0.2, 0.1)\n"
        "dc.step_each(np.repeat(dc.state[None, :], 2, axis=0), 0.2, np.array([0.1, 0.2]))\n"
        "fns = [dc._fn.setup, dc._fn.init, dc._fn.step, dc._fn.run, dc._fn.step_each]\n"
        "print(sum(len(f.stats.cache_misses) for f in fns), "
        "sum(len(f.stats.cache_hits) for f in fns))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], env=env, check=True, capture_output=True, text=True
    )
    misses, hits = (int(v) for v in out.stdout.split())
    assert (misses, hits) == (0, 5)


def test_a_new_plant_file_prepares_the_loops_of_its_size_ahead(tmp_path, monkeypatch):
    """Resolving a plant file the cache has never seen starts one process compiling the
    width-1 loops of its number of states (continuous, then sampled) while sympy builds
    it; nothing is started for a plant file already built, when the cache holds a loop of
    that size, or with the cache off."""
    from aiofl.config.run_config import resolve_plant
    from aiofl.engine.build import prepare

    started = []
    monkeypatch.setattr(
        prepare, "prepare_in_background", lambda plant, specs: started.append((plant, specs))
    )
    monkeypatch.delenv("AIOFL_NO_CACHE", raising=False)
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = tmp_path / "a" / "duffing.toml"
    first.write_text(PLANT_TOML)
    assert resolve_plant(str(first)).n_states == 2
    assert started == [("--states=2", prepare.LOOPS_AHEAD)]
    assert prepare.LOOPS_AHEAD == ((1, False), (1, True))
    again = tmp_path / "b" / "duffing.toml"  # the same text: its module is cached
    again.write_text(PLANT_TOML)
    resolve_plant(str(again))
    assert len(started) == 1
    kernels = tmp_path / "cache" / "kernels"
    kernels.mkdir(parents=True, exist_ok=True)
    (kernels / "loop._tpl_loop_ls1n2_noplant_0123abcd-k.py311.nbi").write_bytes(b"")
    assert prepare.prepare_loops_ahead(2) is None and len(started) == 1
    assert prepare.prepare_loops_ahead(3) is None  # (the stand-in records, returns None)
    assert started[-1] == ("--states=3", prepare.LOOPS_AHEAD)
    monkeypatch.setenv("AIOFL_NO_CACHE", "1")
    assert prepare.prepare_loops_ahead(4) is None and len(started) == 2


def test_the_loops_prepared_without_a_plant_are_those_a_plant_of_the_size_runs():
    """``python -m aiofl.engine.build.prepare --states=N c1`` compiles, without a plant, the very
    instance (recipe fingerprint and loop) every N-state plant then runs; other sizes and
    plant-specific widths are refused with exit status 2."""
    from aiofl.engine.build import prepare
    from aiofl.plants.expressions import MAX_STATES

    pendulum = get_plant("pendulum")
    stand_in = prepare.size_only_plant(2)
    assert compile.fingerprint(instances.recipe(stand_in, 1)) == compile.fingerprint(
        instances.recipe(pendulum, 1)
    )
    prepare.prepare_loops(2, [(1, False)])
    assert instances.instance_for(pendulum, 1) is instances.instance_for(stand_in, 1)
    too_many = f"--states={MAX_STATES + 1}"  # more than a plant file may have
    for bad in (
        ["--states=0", "c1"],
        ["--states=x", "c1"],
        ["--states=2", "c32"],
        [too_many, "c1"],
    ):
        assert prepare.main(bad) == 2
    with pytest.raises(ValueError, match="allowed: 1"):
        prepare.prepare_loops(2, [(32, False)])
