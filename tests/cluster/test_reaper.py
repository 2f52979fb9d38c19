"""The run's process reaper (aerodaas.clusters.reaper): what was below a driver is ended once the driver is gone,
nothing else is touched."""
import os
import subprocess
import sys
import textwrap
import time

from aerodaas.clusters.reaper import descendants, start_time


def _alive(pid: int) -> bool:
    return start_time(pid) is not None


def _gone_within(pid: int, bound_s: float) -> bool:
    end = time.monotonic() + bound_s
    while time.monotonic() < end:
        if not _alive(pid):
            return True
        time.sleep(0.2)
    return False


def test_what_was_below_a_dead_driver_is_ended_and_nothing_else(tmp_path):
    """A 'driver' starts its reaper and a grandchild in a session of its own (as Ray's node processes are), then
    dies without cleaning up: the grandchild is SIGKILLed after the grace; a process the test started itself (not
    below the driver) lives on."""
    bystander = subprocess.Popen(["sleep", "300"])
    pidfile = tmp_path / "grandchild.pid"
    driver = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import subprocess, time
        from aerodaas.clusters import reaper
        reaper.start(period_s=0.1, grace_s=1.0)
        g = subprocess.Popen(["sleep", "300"], start_new_session=True)
        open({str(pidfile)!r}, "w").write(str(g.pid))
        time.sleep(1.0)  # the reaper has seen it
        """)])
    try:
        assert driver.wait(timeout=120) == 0
        grandchild = int(pidfile.read_text())
        assert _gone_within(grandchild, 60.0), "the driver's grandchild outlived it"
        assert bystander.poll() is None and _alive(bystander.pid)
    finally:
        bystander.kill()
        bystander.wait()
        try:
            os.kill(int(pidfile.read_text()), 9)
        except (OSError, ValueError):
            pass


def test_descendants_walks_the_tree_below_a_process():
    p = subprocess.Popen(["bash", "-c", "sleep 30 & sleep 30 & wait"])
    try:
        end = time.monotonic() + 30
        below = []
        while len(below) < 2 and time.monotonic() < end:
            below = descendants(p.pid)
            time.sleep(0.05)
        assert len(below) == 2 and all(_alive(q) for q in below)
        assert os.getpid() not in below and p.pid not in below
    finally:
        for q in descendants(p.pid):
            os.kill(q, 9)
        p.kill()
        p.wait()


def test_a_process_starts_one_reaper_and_knows_it_from_the_process_table():
    """``ensure_started`` starts a reaper for the calling process once: a second call finds it among the process's
    children (``running_for``, read from /proc, no table kept in the module) and starts none; once the process is
    gone its reaper ends too."""
    out = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import os
        from aerodaas.clusters import reaper
        first = reaper.ensure_started()
        print(first.pid, reaper.running_for(os.getpid()), reaper.ensure_started() is None, flush=True)
        os._exit(0)  # not waiting for the reaper: it ends once this process is gone
        """)], capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    pid, running, second_is_none = out.stdout.split()
    assert (running, second_is_none) == ("True", "True"), out.stdout
    assert _gone_within(int(pid), 60.0), "the reaper outlived its driver"
