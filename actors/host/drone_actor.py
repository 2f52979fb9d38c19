"""DroneActor: the Ray actor of one drone (or of ``drones_per_actor`` drones): vehicle backend, flight logic and
mission state machine, cameras, odometry and stat-stream sensors, the waypoint queue and the trajectory scheduler
plug-in, and any analytics deployed with ``colocate=True`` — so a frame exists in the drone's own process and
needs no hop to be captured, recorded or analysed by a colocated analytics.

Named ``aerodaas/<run>/drone/<robot id>`` (``aerodaas/<run>/drones/<first id>+<n - 1>`` for a group) and placed
on a ``tier=edge`` node carrying the robot's edge compute labels. Restartable: while flying it checkpoints each
drone (vehicle state for the simulator, mission state and waypoint queue) to the run's recorder actor every two seconds
a second and at every waypoint; a restarted DroneActor restores the last checkpoint (the simulator's vehicle where
it was; a real vehicle flew on under its own control and is reconnected) and the driver calls :meth:`run` again
with ``resume=True``: the mission goes on from the waypoint it was heading to.
"""
from __future__ import annotations


import ray

from aerodaas.actors.host.base import ActorBase
from aerodaas.actors.drone.checkpoint import restore_drone


@ray.remote(num_cpus=0, max_concurrency=32)
class DroneActor(ActorBase):
    """See the module docstring. Methods beyond :class:`~aerodaas.actors.host.base.ActorBase`: :meth:`run`, :meth:`checkpoint`."""

    def on_restart(self) -> None:
        self.setup()
        rec = self.plane.peer("recorder")
        for d in self.runtime.drones:
            cp = ray.get(rec.last_checkpoint.remote(d.cfg.id), timeout=30)
            if cp is not None:
                restore_drone(d, cp.open())

    def run(self, timeout_s: float | None = None, resume: bool = False) -> dict:
        """Fly this actor's drones to the end of their missions (``resume``: after a restart, from the restored
        checkpoint, without arming or taking off again). Returns robot id -> report."""
        return self.runtime.run(timeout_s, resume=resume)

    def checkpoint(self) -> dict:
        """Robot id -> its current checkpoint (see :mod:`aerodaas.actors.drone.checkpoint`)."""
        return {d.cfg.id: self.runtime.checkpoint_numbers.take(d) for d in self.runtime.drones}
