"""The end-of-run summary says what it does not know instead of printing zeros (a raylet SIGKILL was
summarised as "sim time 0.0 s")."""
from aerodaas.runtime.driver import MissionResult
from aerodaas.runtime.report import format_summary
from aerodaas.runtime.supervise import _lost_report


def test_a_robot_that_never_started_and_one_lost_without_a_checkpoint():
    robots = {"a": {"robot": "a", "outcome": "failed", "error": "another robot could not connect"},
              "b": _lost_report("b", "drone actor lost", None)}
    text = format_summary(MissionResult(outcome="failed", robots=robots, stats={}, latency={}, recording=None,
                                        wall_s=1.0))
    assert "robot a: did not start" in text
    assert "robot b: sim time unknown, waypoints 0/?, final state unknown, battery unknown" in text
    assert "0.0 s" not in text.split("\n", 1)[1]
