"""The layers: imports run one way only, hybrid <- models <- averaging <- vibro, function-local imports included.

Also: the command line starts without the heavy libraries, and the names its parsers show match the registries.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ["hybrid", "models", "averaging", "vibro"]
"""Lowest first: a module may import its own layer and the ones before it."""


def _imported_packages(path: Path, package: str):
    """(line, top-level project package) for every import statement in a file, nested ones included."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: stays inside its own package
                yield node.lineno, package
            elif node.module:
                yield node.lineno, node.module.split(".")[0]


def _violations():
    bad = []
    for rank, package in enumerate(LAYERS):
        for path in sorted((ROOT / package).rglob("*.py")):
            for line, target in _imported_packages(path, package):
                if target in LAYERS and LAYERS.index(target) > rank:
                    bad.append(f"{path.relative_to(ROOT)}:{line} imports {target} (above {package})")
    return bad


def test_imports_point_down_the_layers_only():
    assert _violations() == []


def test_the_walker_sees_function_local_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from vibro.solve import solve\n    import averaging.jump\n")
    assert sorted(t for _, t in _imported_packages(f, "hybrid")) == ["averaging", "vibro"]


def _module_imports(package_dir: Path, dotted: str) -> dict:
    """{module: set of sibling modules it imports} inside one package, function-local imports included
    (``from . import a, b``, ``from .a import x``, ``import pkg.a``, ``from pkg.a import x``)."""
    names = {p.stem for p in package_dir.glob("*.py") if p.stem != "__init__"}
    graph = {}
    for name in names:
        tree = ast.parse((package_dir / f"{name}.py").read_text(encoding="utf-8"))
        out = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level == 1:
                    targets = [base.split(".")[0]] if base else [a.name for a in node.names]
                elif node.level == 0 and base.startswith(dotted + "."):
                    targets = [base[len(dotted) + 1:].split(".")[0]]
                else:
                    targets = []
            elif isinstance(node, ast.Import):
                targets = [a.name[len(dotted) + 1:].split(".")[0] for a in node.names
                           if a.name.startswith(dotted + ".")]
            else:
                continue
            out |= {t for t in targets if t in names and t != name}
        graph[name] = out
    return graph


def _cycle(graph: dict) -> list | None:
    """One import cycle of ``graph`` as a list of modules (first = last), or None."""
    state: dict = {}
    stack: list = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        state[node] = 2
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_the_stochastic_engine_has_no_import_cycle():
    """hybrid/stochastic imports in one direction: no module reaches itself through its imports (function-local
    ones included), so each piece (code generator, executor, runners, front ends) stands on the ones below."""
    graph = _module_imports(ROOT / "hybrid" / "stochastic", "hybrid.stochastic")
    assert {"_auto_exec", "_runner", "_auto_runner", "_front"} <= set(graph)
    assert _cycle(graph) is None, " -> ".join(_cycle(graph))


def _uses(needles: tuple) -> dict:
    """{needle: the project's source files (relative paths) whose code, not their comments, contains it}."""
    found: dict = {n: set() for n in needles}
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            code = "\n".join(line.split("#", 1)[0] for line in path.read_text(encoding="utf-8").splitlines())
            for n in needles:
                if n in code:
                    found[n].add(str(path.relative_to(ROOT)))
    return found


def test_one_code_generator_and_one_executor():
    """Every Monte Carlo kernel comes from one generator, and every run of chunks (the ensembles of both front ends,
    first passage, splitting, snapshots, Welch spectra) goes through one executor: only these files define a chunk
    kernel or start threads or Dask tasks."""
    others = ("ProcessPoolExecutor", "multiprocessing", "Thread(", "import threading", "client.map(", "delayed(",
              ".compute(")
    found = _uses(("def run_chunk(state", "def event_step(", "ThreadPoolExecutor(", ".submit(") + others)
    generator, executor = "hybrid/stochastic/_auto_codegen.py", "hybrid/stochastic/_auto_exec.py"
    assert found["def run_chunk(state"] == {generator}
    assert found["def event_step("] == {generator}  # the CUDA target prints the generator's own (a doctest names it)
    assert found["ThreadPoolExecutor("] == found[".submit("] == {executor}
    assert not any(found[n] for n in others), {n: found[n] for n in others if found[n]}


def test_the_cycle_finder_sees_a_function_local_cycle(tmp_path):
    (tmp_path / "a.py").write_text("from . import b\n")
    (tmp_path / "b.py").write_text("def f():\n    from .c import x\n")
    (tmp_path / "c.py").write_text("import pkg.a\n")
    graph = _module_imports(tmp_path, "pkg")
    assert graph == {"a": {"b"}, "b": {"c"}, "c": {"a"}}
    assert _cycle(graph) == ["a", "b", "c", "a"]
    (tmp_path / "c.py").write_text("import pkg\n")
    assert _cycle(_module_imports(tmp_path, "pkg")) is None


def test_cli_names_match_the_registries():
    from averaging import METHODS
    from hybrid.stochastic import SCHEMES
    from models import MODELS
    from vibro.cli import names

    assert names.SCHEMES == tuple(sorted(SCHEMES))
    assert names.DENSITY_METHODS == tuple(sorted(METHODS))
    assert names.MODELS == tuple(sorted(MODELS))
    from vibro.solve.solver import METHODS as SOLVE_METHODS

    assert names.SOLVE_METHODS == SOLVE_METHODS


def test_cli_help_imports_no_heavy_library():
    # what makes `vibro --help` slow is importing sympy, numba or scipy; assert on the modules, not on a time. One
    # fresh interpreter runs every help in turn and lists the heavy modules after each: while none is imported, each
    # help starts as it would in an interpreter of its own
    heavy = ("sympy", "numba", "scipy", "matplotlib", "pandas")
    argvs = [["--help"], ["--version"], ["mc", "--help"], ["pdf", "--help"], ["orbit", "--help"], ["solve", "--help"],
             ["figure", "--help"]]
    code = (f"import sys; from vibro.cli import main\nfor argv in {argvs!r}:\n    try:\n        main(argv)\n"
            f"    except SystemExit:\n        pass\n"
            f"    print('HEAVY', argv, sorted(m for m in {heavy!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    lines = [line for line in out.splitlines() if line.startswith("HEAVY ")]
    assert lines == [f"HEAVY {argv!r} []" for argv in argvs], lines


def test_solve_by_fpk_imports_only_what_it_uses(tmp_path):
    # start-up is most of `vibro solve`'s cost (issue 23): the fpk path needs sympy, numpy and scipy.sparse, not
    # pandas (the CSV is written by csv_text), scipy.interpolate/optimize/special/integrate or the engines
    unused = ("pandas", "scipy.integrate", "scipy.interpolate", "scipy.optimize", "scipy.special", "matplotlib",
              "numba", "heyoka", "dask")
    out = tmp_path / "p.csv"
    argv = ["solve", "--method", "fpk", "--tol", "0.05", "--no-progress", "--out", str(out)]
    code = (f"import sys; from vibro.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
            f"print(sorted(m for m in {unused!r} if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.read_text().startswith("H,p\n")
    assert res.stdout.strip().splitlines()[-1] == "[]"
