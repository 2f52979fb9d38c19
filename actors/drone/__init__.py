"""One drone inside its actor: :class:`~aerodaas.actors.drone.component.DroneComponent` and the objects it owns
(its flights, deadlines, gimbal, odometry, end of run, navigation inbox, mission plan log, checkpoints). Edges run
one way: the drone builds its parts and hands each what it needs; no part holds or imports the drone."""
