"""A ground rover patrol (docs/extending-vehicles.md): a rover on the ``ground_rover``
backend (examples/plugins/aerodaas_example_plugins/rover.py, a VehicleBackend written from scratch, installed through
the package's entry points) drives three patrol points on the ground (z = 0) in order, stopping 1 s at each. It
needs no take-off: the drone arms it and it drives (ARMED -> HOVERING -> NAVIGATING, never TAKING_OFF); at the end
its "landing" is a stop.
Run: aerodaas run examples/plugins/app/rover_patrol.py --record rover.mcap"""
from aerodaas import *

env = Environment("rover_patrol.json")
rover = env.get_robot_by_id("rover")
patrol = [Waypoint(id=f"p{i}", x=x, y=y, z=0.0, hover_duration=1.0)
          for i, (x, y) in enumerate([(10.0, 0.0), (10.0, 8.0), (0.0, 8.0)], start=1)]
rover.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, patrol, SchedulingType.ORDERED))
result = rover.start_mission()
