"""Run the docstring examples of every public module and the ``>>>`` examples of the documentation pages
(they are the short examples users read)."""

import doctest
import importlib
import pkgutil
import re
from pathlib import Path

import pytest

PACKAGES = ["hybrid", "models", "averaging", "vibro"]
ROOT = Path(__file__).resolve().parent.parent
DOC_PAGES = sorted(p for p in (ROOT / "docs").rglob("*.md")  # pages with a prompt at the start of a line
                   if "_build" not in p.parts and re.search(r"^\s*>>> ", p.read_text(), re.MULTILINE))


def _modules():
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        yield pkg
        for info in pkgutil.walk_packages(mod.__path__, prefix=f"{pkg}."):
            if not info.name.endswith("__main__"):  # running it would start the command line
                yield info.name


@pytest.mark.parametrize("name", sorted(set(_modules())))
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{result.failed} doctest(s) failed in {name}"


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_documentation_page_examples(page, monkeypatch):
    monkeypatch.chdir(ROOT)  # the pages name files from the checkout root, as a user in the checkout would
    result = doctest.testfile(str(page), module_relative=False,
                              optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0, f"{result.failed} of {result.attempted} failed in {page}"
