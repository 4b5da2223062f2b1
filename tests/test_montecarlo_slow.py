"""Long Monte Carlo checks (``pytest -m slow``): Dask with a killed worker, weak orders over wider step ranges."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest
from problems import elastic_duffing

from hybrid.stochastic import SCHEMES, simulate_ensemble
from models import DuffingImpact

pytestmark = pytest.mark.slow


def test_dask_worker_killed_mid_run_gives_the_thread_numbers(tmp_path):
    distributed = pytest.importorskip("distributed")
    model = DuffingImpact()
    kw = dict(dt=2e-3, paths=64, t_end=12000.0, t_burn=50.0, seed=12, xy_bins=(16, 16), chunk_paths=4)
    local = simulate_ensemble(model, "milstein", **kw)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = distributed.Client(cluster)
    try:
        pids = sorted(client.run(os.getpid).values())
        out = {}
        runner = threading.Thread(target=lambda: out.update(s=simulate_ensemble(
            model, "milstein", scheduler=client, checkpoint=tmp_path, checkpoint_every=1, **kw)))
        runner.start()
        deadline = time.time() + 120
        while not (tmp_path / "mc_checkpoint.npz").exists() and time.time() < deadline:
            time.sleep(0.02)  # the first chunk is done: both workers are busy with the next ones
        assert runner.is_alive(), "the run ended before the kill; make it longer"
        os.kill(pids[0], signal.SIGKILL)
        runner.join(timeout=300)
        assert not runner.is_alive()
    finally:
        client.close()
        cluster.close()
    remote = out["s"]
    with np.load(tmp_path / "mc_checkpoint.npz") as d:
        assert len(d["chunk_ids"]) == 16
    for f in ("h_counts", "xy_counts", "v_counts", "chunk_counts", "chunk_sums", "chunk_ids"):
        assert np.array_equal(getattr(local, f), getattr(remote, f)), f


def _biases(scheme, dts, quantity, paths, t_end, seed):
    model, exact = elastic_duffing(delta=1.0, a=1.0, b=0.2, c=0.5, D=0.5)
    target = {"mean_y2": exact.mean_y2(), "mean_x2": exact.mean_x2(),
              "impact_rate": 2 * exact.impact_rate_per_wall()}[quantity]
    out, cis = [], []
    for dt in dts:
        s = simulate_ensemble(model, scheme, dt=dt, paths=paths, t_end=t_end, t_burn=20.0, seed=seed, h_max=20.0,
                              xy_bins=None, check_dt=False)
        e = getattr(s, quantity)
        out.append(abs(e.value - target))
        cis.append(e.ci)
    return np.array(out), np.array(cis)


@pytest.mark.parametrize("scheme,quantity,dts", [
    ("splitting", "mean_x2", [0.4, 0.2, 0.1]),
    ("splitting", "mean_y2", [0.4, 0.28, 0.2]),
    ("milstein", "impact_rate", [0.2, 0.1, 0.05, 0.025]),
    ("em", "mean_x2", [0.1, 0.05, 0.025]),
    ("naive", "mean_x2", [0.1, 0.05, 0.025]),
])
def test_weak_orders_with_elastic_barriers_over_a_wide_step_range(scheme, quantity, dts):
    b, ci = _biases(scheme, dts, quantity, paths=4096, t_end=4000.0, seed=17)
    assert np.all(b > 3 * ci), (b, ci)
    slope = float(np.polyfit(np.log(dts), np.log(b), 1)[0])
    assert abs(slope - SCHEMES[scheme].weak_order_barriers) < 0.3, (slope, b, ci)
