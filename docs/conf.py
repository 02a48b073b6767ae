"""Sphinx configuration of the aiofl manual (``make docs``).

Sphinx, because aiofl's docstrings are already reStructuredText with Sphinx roles
(``:func:``, ``:math:``, ``.. code-block::``) and numpydoc sections: autodoc renders them as
written.  The pages are Markdown (myst-parser); the gallery is sphinx-gallery, executed at
every build; the configuration reference is generated from the pydantic schema by
``_ext/config_reference.py``.  Nothing is fetched at build time: no intersphinx, a theme
(furo) that ships its assets.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(ROOT / "src"))  # the worktree's aiofl, not another install
os.environ.setdefault("MPLBACKEND", "Agg")

import aiofl  # noqa: E402

project = "aiofl"
author = "aiofl developers"
copyright = "aiofl developers"
release = version = aiofl.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "config_reference",
    "cli_reference",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "**.zip"]

# --- Markdown pages
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]  # a page may start below H1 in its own flow

# --- API reference
autosummary_generate = False
autodoc_default_options: dict[str, object] = {}
autodoc_typehints = "none"  # numpydoc sections carry the types; signatures stay readable
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# --- the gallery: every example runs at every build
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "min_reported_time": 1,
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "capture_repr": (),
    "plot_gallery": os.environ.get("AIOFL_DOCS_GALLERY", "True"),
}

# --- HTML
html_theme = "furo"
html_title = f"aiofl {release}"
html_static_path: list[str] = []
html_show_sourcelink = False
# math: MathJax, loaded by the reader's browser (the build fetches nothing)


# --- one page per public module (docs/reference/api/, written here, not committed)
API_MODULES = [
    line.strip()
    for line in (HERE / "reference" / "api-modules.txt").read_text().splitlines()
    if line.strip() and not line.startswith("#")
]


def _write_api_pages() -> None:
    out = HERE / "reference" / "api"
    out.mkdir(exist_ok=True)
    wanted = set()
    for line in API_MODULES:
        name, *how = line.split()
        page = out / f"{name}.rst"
        wanted.add(page.name)
        members = "" if "docstring" in how else "   :members:\n"
        for opt in how:
            if opt.startswith("exclude="):
                members += f"   :exclude-members: {opt[len('exclude=') :].replace(',', ', ')}\n"
        text = f"{name}\n{'=' * len(name)}\n\n.. automodule:: {name}\n{members}"
        if not page.is_file() or page.read_text() != text:
            page.write_text(text)
    for page in out.glob("*.rst"):
        if page.name not in wanted:
            page.unlink()


_write_api_pages()


# --- nitpicky: a reference to a public object of a documented module must resolve;
# references to other libraries (no intersphinx: the build is offline), to aiofl's internal
# modules and names outside a module's __all__ (which have no entry), and to attributes
# and constants (without a doc comment they have no entry) are let through
nitpicky = True
DOCUMENTED = {line.split()[0] for line in API_MODULES if "docstring" not in line.split()}


def _module_of(target: str) -> str | None:
    """The longest importable module prefix of a dotted target."""
    parts = target.split(".")
    for n in range(len(parts), 0, -1):
        name = ".".join(parts[:n])
        if name in sys.modules:
            return name
    return None


def _quiet_undocumented(app: object, domain: object, node: object) -> bool | None:
    if getattr(domain, "name", "") != "py":
        return None
    target = node.get("reftarget", "")  # type: ignore[attr-defined]
    module = _module_of(target) if target.startswith("aiofl") else None
    if module is None or module not in DOCUMENTED:
        return True  # another library, a private name, or a module without a page
    name = target[len(module) + 1 :].split(".")[0]
    public = getattr(sys.modules[module], "__all__", None)
    if name and public is not None and name not in public:
        return True  # documented modules show their __all__; the rest is internal
    if node.get("reftype") in ("attr", "data"):  # type: ignore[attr-defined]
        return True  # an attribute or constant without a doc comment has no entry
    return None


def setup(app: object) -> None:
    app.connect("warn-missing-reference", _quiet_undocumented)  # type: ignore[attr-defined]
