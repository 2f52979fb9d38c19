"""Tower inspection (paper §6.6, pattern 5): fly waypoints to locate a structure; on finding it the locating
mission is aborted and replaced by a vertical inspection pattern around it (5 m to 35 m, four faces), capturing
frames all the way, then the drone lands. The structure is recognised from a reference photo of it.
Needs real imagery (AERODAAS_DATA_DIR)."""
from aerodaas import *
from aerodaas.analytics.extra import InspectionPlanner, StructureLocator

env = Environment("tower_inspection.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
frames = drone.get_sensor_by_id("cam1").get_data_stream()

area = [(4, 4), (4, 22), (14, 22), (14, 4)]
locate = AeroNavigation(NavigationType.DISTANCE_DRIVEN,
                        [Waypoint(id=f"wp{i + 1}", x=x, y=y, z=10) for i, (x, y) in enumerate(area)],
                        SchedulingType.UNORDERED, name="locate")
drone.navigate(scheduler.generate_navigation(locate))

locator = StructureLocator("imagery/caliterra/IMG_9354.jpg", crop=(2086, 1504, 2386, 1804), size_m=3.0)
locator.deploy(edge)
planner = InspectionPlanner(base_altitude=5, top_altitude=35, step_m=10, radius_m=6, faces=4)
planner.deploy(edge)
inspection = planner.analyse(locator.analyse(frames))
scheduler.add_navigation(PriorityQueue(inspection, priority=1, replace=True))

result = drone.start_mission()
