"""How the documentation's gallery runs ``examples/*.py``: as scripts, with the figures they draw.

The examples are plain scripts: a docstring, a ``main()`` and ``sys.exit(main(...))``; they draw with matplotlib
and save their figures (02, 03, 05) or leave them open. :func:`run_as_script` makes ``sys.exit(0)`` end the script
normally and ``sys.exit(1)`` (a failed self-check) fail the build, and remembers every figure the script saves;
:func:`scrape_figures` shows each of those figures, then those left open, drawn by the script itself. Named by string
in ``conf.py``'s ``sphinx_gallery_conf``.
"""

from __future__ import annotations

import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def reset_argv(gallery_conf, script_vars) -> list[str]:
    """Each example's command line: ``--quick`` for the scripts that offer a small size."""
    script = Path(script_vars["src_file"]).name
    return ["--quick"] if "--quick" in (EXAMPLES / script).read_text() else []


class ExampleExit(Exception):
    """A gallery example ended with a non-zero status: one of its self-checks failed."""


class _ScriptRun:
    """State of the example being run: the real ``sys.exit`` and ``Figure.savefig``, and the figures saved."""

    saved: list = []
    real_exit = None
    real_savefig = None


def _exit(status=0):
    if status not in (0, None):
        raise ExampleExit(f"the example exited with status {status!r}: a self-check failed")


def _savefig(fig, *args, **kwargs):
    if not any(fig is f for f in _ScriptRun.saved):
        _ScriptRun.saved.append(fig)
    return _ScriptRun.real_savefig(fig, *args, **kwargs)


def run_as_script(gallery_conf, fname, when="before") -> None:
    """Before an example: its ``sys.exit`` and ``savefig`` as described above. After it: the real ones back."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    if when == "before":
        _ScriptRun.saved = []
        _ScriptRun.real_exit, _ScriptRun.real_savefig = sys.exit, Figure.savefig
        sys.exit, Figure.savefig = _exit, _savefig
    elif _ScriptRun.real_exit is not None:
        sys.exit, Figure.savefig = _ScriptRun.real_exit, _ScriptRun.real_savefig
        _ScriptRun.real_exit = _ScriptRun.real_savefig = None


def scrape_figures(block, block_vars, gallery_conf) -> str:
    """sphinx-gallery image scraper: the figures the example saved, then those it left open, each once."""
    import matplotlib.pyplot as plt
    from sphinx_gallery.scrapers import figure_rst

    figures = list(_ScriptRun.saved)
    for num in plt.get_fignums():
        fig = plt.figure(num)
        if not any(fig is f for f in figures):
            figures.append(fig)
    _ScriptRun.saved = []
    paths = []
    for fig, path in zip(figures, block_vars["image_path_iterator"]):
        fig.savefig(path, dpi=96)
        paths.append(path)
    plt.close("all")
    return figure_rst(paths, gallery_conf["src_dir"])
