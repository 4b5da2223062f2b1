"""Sphinx configuration of the vibro-impact documentation site.

Build from the checkout root with ``python -m sphinx -W -b html docs docs/_build/html`` (``pip install -e
".[docs]"`` first). The gallery runs every script of ``examples/`` with ``--quick`` where the script takes it;
``VIBRO_DOCS_GALLERY=0`` skips running them (pages without outputs, for a fast look at the text).
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS))

import vibro  # noqa: E402

project = "vibro-impact"
author = "the vibro-impact developers"
copyright = "the vibro-impact developers, BSD-3-Clause"
release = vibro.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
smartquotes = False  # keep -- in command lines as typed
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "gallery/*.png", "charts/*.csv", "**.ipynb_checkpoints",
                    "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.json",
                    "auto_examples/*.md5", "auto_examples/*.codeobj.json"]
# a markdown page's "## Section" gets an anchor, so pages can link to sections of one another
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

# API reference: one page per public object, from the numpydoc docstrings
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "inherited-members": False, "show-inheritance": True}
autodoc_typehints = "none"  # numpydoc's Parameters sections already give the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = False
numpydoc_xref_param_type = False

html_theme = "pydata_sphinx_theme"
html_title = f"vibro-impact {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "header_links_before_dropdown": 5,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []
html_show_sourcelink = False

# ---- the gallery: examples/*.py, run as scripts ----------------------------------------------------------------
#
# The examples are plain scripts: a docstring, a main() and ``sys.exit(main(...))``; they draw with matplotlib and
# save their figures (02, 03, 05) or leave them open. docs/gallery_support.py shows every figure a script saved or
# left open, drawn by the script itself; ``sys.exit(0)`` ends the script normally and ``sys.exit(1)`` (a failed
# self-check) fails the build.

RUN_GALLERY = os.environ.get("VIBRO_DOCS_GALLERY", "1") != "0"

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/\d\d_",
    "plot_gallery": RUN_GALLERY,
    # named by string (docs/gallery_support.py), so that the configuration pickles and Sphinx can cache it
    "reset_argv": "gallery_support.reset_argv",
    "reset_modules": ("gallery_support.run_as_script",),
    "reset_modules_order": "both",
    "image_scrapers": ("gallery_support.scrape_figures",),
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "abort_on_example_error": True,
    "min_reported_time": 1,
    "promote_jupyter_magic": False,
    "matplotlib_animations": False,
    "capture_repr": (),
}


# ---- the API reference: generated from the public modules' ``__all__`` --------------------------------------------
#
# Each package page lists its public modules; each public function or class gets its own page (autosummary), once,
# under the module that defines it (a name re-exported elsewhere links there). The pages are written here, at
# configuration time, so that a name added to an ``__all__`` appears without editing the docs.

API_PACKAGES = {
    "hybrid": ["hybrid", "hybrid.deterministic", "hybrid.stochastic", "hybrid.errors", "hybrid.io", "hybrid.sizes",
               "hybrid.resolution"],
    "models": ["models", "models.automata", "models.excitation"],
    "averaging": ["averaging", "averaging.chain", "averaging.phase_plane"],
    "vibro": ["vibro.solve", "vibro.studies.figures", "vibro.studies.validity", "vibro.studies.workprecision",
              "vibro.studies.plots", "vibro.provenance", "vibro.cli"],
}
API_DIR = DOCS / "api"


def _public_names(modname: str) -> list[str]:
    """``__all__``, or else the public functions and classes the module defines itself."""
    import importlib
    import inspect

    module = importlib.import_module(modname)
    names = getattr(module, "__all__", None)
    if names is None:
        names = [n for n, obj in vars(module).items() if not n.startswith("_")
                 and (inspect.isfunction(obj) or inspect.isclass(obj)) and obj.__module__ == modname]
    return [n for n in names if callable(getattr(module, n, None)) and not n.startswith("_")]


def _canonical_homes() -> dict[int, str]:
    """For each public object, the listed module it is documented under: the one nearest its definition."""
    import importlib

    homes: dict[int, str] = {}
    for modules in API_PACKAGES.values():
        for modname in modules:
            module = importlib.import_module(modname)
            for name in _public_names(modname):
                obj = getattr(module, name)
                defined = getattr(obj, "__module__", "") or ""
                current = homes.get(id(obj))
                if current is None or (defined.startswith(modname) and len(modname) > len(current)):
                    homes[id(obj)] = modname
    return homes


def _first_line(modname: str) -> str:
    import importlib

    doc = (importlib.import_module(modname).__doc__ or "").strip()
    return doc.split("\n\n")[0].replace("\n", " ")


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def write_api_pages() -> None:
    """Write ``docs/api/<package>.rst`` and ``docs/api/facade.rst`` from the modules' public names."""
    import importlib

    homes = _canonical_homes()
    for package, modules in API_PACKAGES.items():
        lines = [f"``{package}``", "=" * (len(package) + 4), ""]
        if package == "vibro":
            lines += ["The application layer: method choice, studies, provenance and the command line. The names of",
                      "``import vibro`` are listed in :doc:`facade`.", ""]
        for modname in modules:
            module = importlib.import_module(modname)
            title = f"``{modname}``" + (" (the package itself)" if modname == package else "")
            lines += [title, "-" * len(title), "", f".. module:: {modname}", "", _first_line(modname), "",
                      f".. currentmodule:: {modname}", ""]
            own, elsewhere = [], []
            for name in _public_names(modname):
                home = homes[id(getattr(module, name))]
                (own if home == modname else elsewhere).append((name, home))
            if own:
                lines += [".. autosummary::", "   :toctree: generated/", "   :nosignatures:", ""]
                lines += [f"   {name}" for name, _ in own] + [""]
            if elsewhere:
                links = ", ".join(f":py:obj:`{name} <{home}.{name}>`" for name, home in elsewhere)
                lines += [f"Also here: {links}.", ""]
        _write_if_changed(API_DIR / f"{package}.rst", "\n".join(lines))

    lines = ["The ``vibro`` facade", "====================", "",
             "``import vibro`` gives the everyday names of the four packages in one place, imported lazily (``import",
             "vibro`` itself stays fast). Each name is the object documented at its home:", "",
             ".. list-table::", "   :header-rows: 1", "", "   * - ``vibro.`` name", "     - documented as"]
    for name in sorted(vibro.__all__, key=str.lower):
        obj = getattr(vibro, name)
        if not callable(obj):
            continue
        home = homes.get(id(obj))
        target = f":py:obj:`{home}.{name}`" if home else "(not in the reference)"
        lines += [f"   * - ``{name}``", f"     - {target}"]
    lines += ["", f"``vibro.__version__`` is the package version ({release}).", ""]
    _write_if_changed(API_DIR / "facade.rst", "\n".join(lines))


write_api_pages()


# ---- docstrings: plain-text mathematics as the code writes it ------------------------------------------------------
#
# The docstrings write absolute values as |x| and argument lists as (x, *values); reST would read the first as a
# substitution and the second as the start of emphasis. Outside ``literals`` both are escaped before numpydoc and
# autodoc read them (the project uses neither substitutions nor single-star emphasis that does not close on its line).

_ABS = re.compile(r"(?<![\\|\w`])\|(?=[^\s|])([^|`\n]*?[^\s|\\])\|(?![|\w`])")
_STAR = re.compile(r"(?<=[\s(\[,])\*(?=[\w(])")
_EMPHASIS = re.compile(r"(?<![\w*])\*[^\s*]([^*]*[^\s*\\])?\*(?![\w*])")


def escape_plain_math(text: str) -> str:
    """Escape ``|x|`` and an unclosed ``*name`` in one line of a docstring, leaving ``literals`` alone.

    Examples
    --------
    >>> escape_plain_math("the speed |y-| at the wall, f(x, *values), ``|x|``")
    'the speed \\\\|y-\\\\| at the wall, f(x, \\\\*values), ``|x|``'
    """
    parts = text.split("``")
    for i in range(0, len(parts), 2):  # even parts are outside literals
        part = _ABS.sub(r"\\|\1\\|", parts[i])
        if not _EMPHASIS.search(part):
            part = _STAR.sub(r"\\*", part)
        parts[i] = part
    return "``".join(parts)


def _escape_docstring(app, what, name, obj, options, lines):
    in_doctest = False
    for i, line in enumerate(lines):
        stripped = line.lstrip()
        if stripped.startswith(">>>") or stripped.startswith("..."):
            in_doctest = True
        elif not stripped:
            in_doctest = False
        if not in_doctest:
            lines[i] = escape_plain_math(line)


def setup(app):
    app.connect("autodoc-process-docstring", _escape_docstring, priority=100)
