"""The Monte Carlo on a dask.distributed cluster (issue #11): same metrics as in-process."""

from __future__ import annotations

import json
import os
import sys

import pytest

distributed = pytest.importorskip("distributed")

from fte_casadi.sim import simulate  # noqa: E402
from fte_casadi.sim._engine import chunk_task  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as c:
        yield c


def _doc(res):
    m = dict(res.metrics)
    m.pop("wall_s")
    return m


@pytest.mark.slow
def test_cluster_run_equals_in_process(cluster, plants, real_designs):
    from fte_casadi.plants import SCENARIOS

    sc = SCENARIOS["manipulator"]()
    kw = dict(paths=64, seed=1, progress=False, chunk=16)
    here = simulate(real_designs["manipulator"], plants["manipulator"], sc, **kw)
    there = simulate(
        real_designs["manipulator"], plants["manipulator"], sc, scheduler=cluster.scheduler_address, **kw
    )
    assert _doc(here) == _doc(there)


def kill_once(marker, *args):
    """A chunk task that takes its worker process down the first time it runs."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(1)
    return chunk_task(*args)


def test_a_lost_worker_is_retried_without_changing_the_result(cluster, plants, real_designs, tmp_path):
    import cloudpickle

    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim._cluster import run_on_cluster
    from fte_casadi.sim._engine import SCALES, resolve_dt

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    d, p = real_designs["manipulator"], plants["manipulator"]
    sc = SCENARIOS["manipulator"]()
    dt = resolve_dt(d, sc, None)[0]
    marker = str(tmp_path / "killed")

    def task(*args):
        return kill_once(marker, *args)

    got = dict(run_on_cluster(cluster.scheduler_address, d, p, sc, dt, dict(SCALES), 3, 24, 8, task=task))
    assert os.path.exists(marker)  # a worker was lost
    ref = dict(
        run_on_cluster(cluster.scheduler_address, d, p, sc, dt, dict(SCALES), 3, 24, 8, task=chunk_task)
    )
    for a in ref:
        assert (got[a][0] == ref[a][0]).all() and (got[a][1] == ref[a][1]).all()


@pytest.mark.slow
def test_cli_scheduler_equals_in_process(cluster):
    from click.testing import CliRunner

    from fte_casadi.cli import main

    args = ["simulate", "manipulator", "--paths", "64", "--seed", "1", "--json", "--quiet"]
    a = CliRunner().invoke(main, args)
    b = CliRunner().invoke(main, args + ["--scheduler", cluster.scheduler_address])
    assert a.exit_code == 0 and b.exit_code == 0, (a.output, b.output)
    ma, mb = json.loads(a.stdout), json.loads(b.stdout)
    ma.pop("wall_s"), mb.pop("wall_s")
    assert ma == mb


@pytest.mark.slow
def test_unreachable_scheduler_is_a_clear_error(plants, real_designs, monkeypatch):
    from fte_casadi.errors import SimulationError
    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim import _cluster

    monkeypatch.setattr(_cluster, "CONNECT_TIMEOUT", 1.0)  # the same refusal, after 1 s of retries, not 10

    with pytest.raises(SimulationError, match="cannot reach the dask scheduler"):
        simulate(real_designs["manipulator"], plants["manipulator"], SCENARIOS["manipulator"](), paths=4, seed=0,
                 progress=False, scheduler="tcp://127.0.0.1:9")  # fmt: skip


def test_sweep_on_the_cluster_equals_in_process(cluster, plants, real_designs):
    """One client for all points of a sweep; each point's metrics as in-process."""

    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim._sweep import sweep

    d, p = real_designs["manipulator"], plants["manipulator"]
    sc = SCENARIOS["manipulator"]().until(3.0)
    kw = dict(paths=24, seed=6, progress=False)
    here = sweep(d, p, sc, {"d_scale": [0.0, 2.0]}, **kw)
    there = sweep(d, p, sc, {"d_scale": [0.0, 2.0]}, scheduler=cluster.scheduler_address, **kw)
    for a, b in zip(here, there):
        a["metrics"].pop("wall_s"), b["metrics"].pop("wall_s")
    assert here == there and here[0]["metrics"] != here[1]["metrics"]
