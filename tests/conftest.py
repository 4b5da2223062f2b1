import os
import sys

# tests import the shared problem library as ``problems``
sys.path.insert(0, os.path.dirname(__file__))
os.environ.setdefault("MPLBACKEND", "Agg")


# ---------------------------------------------------------------------------------------------- compile budget
# VIBRO_TEST_COMPILE_LOG=<dir> python -m pytest ...: every numba compile in the test processes (not in the
# subprocesses some tests start) is written to <dir>/<pid>.jsonl with its test and CPU seconds, and the run ends
# with the kernels compiled and the tests that compiled most. Cold-suite cost is mostly these compiles; a test that
# compiles a kernel no other test needs shows up here. Use an empty directory and an empty VIBRO_CACHE_DIR.
_COMPILE_LOG = os.environ.get("VIBRO_TEST_COMPILE_LOG")


def pytest_configure(config):
    if not _COMPILE_LOG:
        return
    import json
    import threading
    import time

    from numba.core import event

    os.makedirs(_COMPILE_LOG, exist_ok=True)
    state = threading.local()

    class CompileLog(event.Listener):
        def on_start(self, ev):  # nested compiles (the kernel's helpers) count in the outermost one
            state.depth = getattr(state, "depth", 0) + 1
            if state.depth == 1:
                py_func = getattr(ev.data["dispatcher"], "py_func", None)
                state.name = f"{getattr(py_func, '__module__', '?')}.{getattr(py_func, '__qualname__', '?')}"
                state.cpu0 = time.process_time()

        def on_end(self, ev):
            state.depth -= 1
            if state.depth == 0:
                record = dict(function=state.name, cpu=round(time.process_time() - state.cpu0, 3),
                              test=os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" ", 1)[0])
                with open(os.path.join(_COMPILE_LOG, f"{os.getpid()}.jsonl"), "a") as fh:
                    fh.write(json.dumps(record) + "\n")

    event.register("numba:compile", CompileLog())


def pytest_terminal_summary(terminalreporter):
    if not _COMPILE_LOG or hasattr(terminalreporter.config, "workerinput"):
        return
    import collections
    import glob
    import json

    records = [json.loads(line) for path in glob.glob(os.path.join(_COMPILE_LOG, "*.jsonl")) for line in open(path)]
    kernels = [r for r in records if r["function"].startswith("vibro_auto")]
    per_test = collections.defaultdict(list)
    for r in kernels:
        per_test[r["test"]].append(r["cpu"])
    write = terminalreporter.write_line
    write(f"numba compiles: {len(records)} ({sum(r['cpu'] for r in records):.0f} CPU s); Monte Carlo kernel entry "
          f"points: {len(kernels)} ({sum(r['cpu'] for r in kernels):.0f} CPU s) in "
          f"{len({r['function'].rsplit('.', 1)[0] for r in kernels})} modules; log in {_COMPILE_LOG}")
    for test, cpus in sorted(per_test.items(), key=lambda kv: -sum(kv[1]))[:20]:
        write(f"  {sum(cpus):6.1f} s  {len(cpus)} kernel(s)  {test}")
