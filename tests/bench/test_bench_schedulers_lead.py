"""``aerodaas bench schedulers``: a run whose edge hosts take longer to configure than the lead time before the run's
time origin configures them again with a longer lead instead of failing (a loaded machine), and gives up with a
clear error only after ``LEAD_TRIES`` overruns. The hosts here are stand-ins whose calls answer through Ray's
object store, as an actor's would."""
from __future__ import annotations

import time

import pytest


class _Call:
    def __init__(self, fn) -> None:
        self.fn = fn

    def remote(self, *args, **kwargs):
        import ray

        return ray.put(self.fn(*args, **kwargs))


class _Host:
    """An edge host whose first ``slow`` configure calls take past the start epoch they are given."""

    def __init__(self, slow: int) -> None:
        self.slow, self.epochs = slow, []
        self.configure = _Call(self._configure)
        self.run_trace = _Call(lambda trace, drain_s: {"edges": [], "trace": list(trace)})
        self.close = _Call(lambda: None)

    def _configure(self, **kw) -> dict:
        self.epochs.append(kw["start_epoch"])
        if len(self.epochs) <= self.slow:
            time.sleep(max(0.0, kw["start_epoch"] - time.time()) + 0.05)  # past the run's time origin
        return {}


def _run(host: _Host):
    from aerodaas.bench.schedulers import _run_one

    return _run_one([host], [["e0"]], [], "EDGE_FIFO", None, [[(0.0, "e0", "d0", "m")]], seed=0,
                    edge_jitter="none", cloud_jitter="none", network=None, drain_s=1.0, reply_lead_ms=100.0)


def test_an_overrun_lead_time_configures_the_hosts_again_with_a_longer_one(ray_session):
    host = _Host(slow=1)
    outs = _run(host)
    assert len(host.epochs) == 2 and outs[0]["trace"] == [(0.0, "e0", "d0", "m")]  # the run went on
    assert "wall_s" in outs[-1]


def test_a_host_that_always_overruns_fails_the_run_with_a_clear_error(ray_session, monkeypatch):
    from aerodaas.bench import schedulers

    monkeypatch.setattr(schedulers, "LEAD_TRIES", 1)
    host = _Host(slow=1)
    with pytest.raises(RuntimeError, match="longer than the run's lead time 1 times"):
        _run(host)
    assert len(host.epochs) == 1
