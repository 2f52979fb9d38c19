"""Gas survey with plug-ins only (docs/extending.md): a drone on the ``gusty_sim`` backend flies a survey line
over a gas plume; its ``gas_concentration`` sensor feeds the ``gas_threshold`` analytics, which makes it hover
where the gas first exceeds the threshold (priority 1 preempts the survey), and the ``gas_plume`` analytics,
which records whether the drone is inside the plume, each crossing, and an event on entering and leaving it; a
``frame_probe`` on the camera is placed per frame by the ``THIN_EDGE_FIFO`` analytics scheduler; the survey's
waypoints, given in no particular order, are flown west to east by the ``eastward_sweep`` trajectory scheduler. The
environment names the backend, the sensor type and the analytics scheduler; the analytics and trajectory-scheduler
classes come from the registry (installed entry points).
Run: aerodaas run examples/plugins/app/gas_survey.py --record gas.mcap"""
from aerodaas import *
from aerodaas.plugins import get_plugin

env = Environment("gas_survey.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("uav")
scheduler = get_plugin("trajectory_scheduler", "eastward_sweep")(env)
env.set_trajectory_scheduler(scheduler)

GasThreshold = get_plugin("analytics", "gas_threshold")
FrameProbe = get_plugin("analytics", "frame_probe")
alarm = GasThreshold(hover_ppm=60.0, rearm_ppm=30.0, hover_s=2.0).deploy(edge)
scheduler.add_navigation(PriorityQueue(alarm.analyse(drone.get_sensor_by_id("gas").get_data_stream()), priority=1))
PlumeTracker = get_plugin("analytics", "gas_plume")
plume = PlumeTracker(enter_ppm=30.0, exit_ppm=15.0).deploy(edge)
plume.analyse(drone.get_sensor_by_id("gas").get_data_stream())  # a status per reading, a crossing, two events
probe = FrameProbe().deploy(edge)
probe.analyse(drone.get_sensor_by_id("cam").get_data_stream())

# any order: the scheduler sweeps west to east (nearest-neighbour would fly wp1, wp3, wp4, wp2)
survey = [Waypoint(id=f"wp{i}", x=x, y=y, z=8.0, hover_duration=0.5)
          for i, (x, y) in [(3, (26, 0)), (1, (8, 0)), (4, (36, 0)), (2, (16, 20))]]
drone.navigate(scheduler.generate_navigation(
    PriorityQueue(AeroNavigation(NavigationType.DISTANCE_DRIVEN, survey, SchedulingType.UNORDERED), priority=2)))
result = drone.start_mission()
