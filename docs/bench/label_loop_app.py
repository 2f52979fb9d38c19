"""The flights of the timed labelling loop (docs/bench/label_loop_timed.py): a lawnmower survey of the packaged
Brighton-beach ground (80 m x 45 m, docs/bench/label_loop.json) while four simulated cars drive loops over it,
camera recorded. Each pass flies the three survey lines at the next altitude of ALTITUDES, so the cars are seen at
several sizes; passes repeat until LOOP_MINUTES (default 10) of flight are planned.
LOOP_COLUMNS=1 flies north-south lines instead (the held-out flight: other views of the same site).

    LOOP_MINUTES=10 aerodaas run docs/bench/label_loop_app.py --record loop.mcap --speedup 5
    LOOP_MINUTES=2 LOOP_ALTITUDES=20 LOOP_COLUMNS=1 aerodaas run docs/bench/label_loop_app.py --record held_out.mcap

With LOOP_MODEL=FILE.onnx the app also runs that detector on every frame (the loop's last step: the app with the
fine-tuned model)."""
import os

from aerodaas import *

ALTITUDES = [float(a) for a in os.environ.get("LOOP_ALTITUDES", "16,24,12,30").split(",")]
MINUTES = float(os.environ.get("LOOP_MINUTES", "10"))
COLUMNS = os.environ.get("LOOP_COLUMNS") == "1"
SPEED = 3.0  # m/s, the robot's max_speed in label_loop.json

env = Environment("label_loop.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)

# planned flight time: legs at SPEED plus the hover and braking at each waypoint (the recording's
# own length is checked with `aerodaas info`)
waypoints, planned, pos, k = [], 0.0, (0.0, 0.0, ALTITUDES[0]), 0
while planned < MINUTES * 60:
    z = ALTITUDES[k % len(ALTITUDES)]
    ys = (-15, 0, 15) if k % 2 == 0 else (15, 0, -15)
    for j, y in enumerate(ys):
        for x in ((-30, 30) if j % 2 == 0 else (30, -30)):
            if COLUMNS:  # north-south lines instead (x and y swapped, clipped to the ground's 45 m)
                x, y = y * 1.6, x * 0.6
            d = ((x - pos[0]) ** 2 + (y - pos[1]) ** 2 + (z - pos[2]) ** 2) ** 0.5
            planned += d / SPEED + 3  # + the 1 s hover and about 2 s of slowing into and out of the waypoint
            waypoints.append(Waypoint(id=f"p{k}-{len(waypoints)}", x=x, y=y, z=z, hover_duration=1))
            pos = (x, y, z)
    k += 1
drone.navigate(scheduler.generate_navigation(PriorityQueue(AeroListData(waypoints), priority=2)))

if os.environ.get("LOOP_MODEL"):
    vehicles = ["car"]
    detector = ObjectDetector(model_path=os.environ["LOOP_MODEL"], classes=vehicles, score_threshold=0.3,
                              input_size=(480, 640))
    detector.deploy(edge)
    detector.analyse(drone.get_sensor_by_id("cam1").get_data_stream())
result = drone.start_mission()
