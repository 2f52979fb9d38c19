"""Analytics scheduler ``THIN_EDGE_FIFO``: EDGE_FIFO (every task on the edge, first come first served) that sheds
every ``keep_every``-th task with the reason ``thin-edge-fifo: shed``, a user's experiment in load shedding. Its
decisions are recorded on ``/<robot>/<analytics>/tasks`` like every scheduler's."""
from __future__ import annotations

from aerodaas.schedulers.analytics_base import Decision, TaskState
from aerodaas.schedulers.analytics_baselines import EdgeFifo


class ThinEdgeFifo(EdgeFifo):
    """See the module docstring."""

    plugin_kind = "analytics_scheduler"
    name = "THIN_EDGE_FIFO"
    keep_every = 3

    def __init__(self, workload) -> None:
        super().__init__(workload)
        self.seen = 0

    def submit(self, task, now_ms):
        self.seen += 1
        if self.seen % self.keep_every == 0:
            return [Decision.drop(task, TaskState.DROPPED_COST, "thin-edge-fifo: shed")]
        return super().submit(task, now_ms)
