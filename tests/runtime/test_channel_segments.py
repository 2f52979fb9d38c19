"""The same-node channel's shared-memory segments (aerodaas.actors.data.channel_slots): a sender and a receiver start
no resource-tracker process (CPython's ``SharedMemory`` starts one per process before 3.13), the bytes one writes are
the bytes the other maps, and a segment whose process died is unlinked by the next segment made on the machine and by
a local run's reaper, never one of a process that still runs. Real processes, /dev/shm as it is."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil
import pytest

from aerodaas.actors.data.channel_slots import Segment, attach, create_segment
from aerodaas.clusters.reaper import SHM_DIR, sweep_segments

ROOT = Path(__file__).resolve().parents[2]


def _python(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, stdout=subprocess.PIPE,
                            text=True)


def _exists(name: str) -> bool:
    return os.path.exists(os.path.join(SHM_DIR, name))


def test_a_sender_and_a_receiver_share_the_bytes_and_start_no_resource_tracker():
    """The sender's slot and a receiver's mapping in two fresh interpreters: the receiver reads what the sender
    wrote, and neither process has a child (a resource tracker would be one)."""
    sender = _python("""
        import time
        from aerodaas.actors.data.channel_slots import Slot
        s = Slot(640 * 480 * 3)
        s.shm.buf[:5] = b"frame"
        print(s.shm.name, flush=True)
        time.sleep(300)
        """)
    try:
        name = sender.stdout.readline().strip()
        receiver = subprocess.run([sys.executable, "-c", textwrap.dedent(f"""
            import psutil
            from aerodaas.actors.data.channel_slots import attach
            m = attach({name!r})
            print(bytes(m.buf[:5]).decode(), m.size, len(psutil.Process().children(recursive=True)))
            m.close()
            """)], cwd=ROOT, capture_output=True, text=True, timeout=120, check=True)
        assert receiver.stdout.split() == ["frame", str(640 * 480 * 3), "0"]
        assert psutil.Process(sender.pid).children(recursive=True) == []
        assert _exists(name)
    finally:
        sender.kill()
        sender.wait(timeout=60)
    sweep_segments({sender.pid})


def test_a_dead_processs_segments_are_swept_by_the_next_segment_and_a_live_ones_kept():
    code = """
        import os, time
        from aerodaas.actors.data.channel_slots import create_segment
        s = create_segment(4096)
        print(s.name, flush=True)
        {end}
        """
    dead = _python(code.format(end="os._exit(0)  # without unlinking: as a SIGKILLed actor"))
    live = _python(code.format(end="time.sleep(300)"))
    try:
        dead_name, live_name = dead.stdout.readline().strip(), live.stdout.readline().strip()
        assert dead.wait(timeout=60) == 0 and _exists(dead_name) and _exists(live_name)
        mine = create_segment(64)  # sweeps first
        try:
            assert not _exists(dead_name) and _exists(live_name)
        finally:
            mine.close()
            mine.unlink()
    finally:
        live.kill()
        live.wait(timeout=60)
    assert sweep_segments({live.pid}) == [live_name] and not _exists(live_name)


def test_the_reaper_unlinks_what_a_dead_drivers_actors_left(tmp_path):
    """A 'driver' starts its reaper and an 'actor' in a session of its own that makes a segment, then dies: once the
    reaper has killed the actor, the segment is gone too."""
    pidfile = tmp_path / "actor.txt"
    driver = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import subprocess, sys, time
        from aerodaas.clusters import reaper
        reaper.start(period_s=0.1, grace_s=0.5)
        actor = subprocess.Popen([sys.executable, "-c", "import time\\n"
                                  "from aerodaas.actors.data.channel_slots import create_segment\\n"
                                  "s = create_segment(4096)\\n"
                                  "open({str(pidfile)!r}, 'w').write(s.name)\\n"
                                  "time.sleep(300)"], start_new_session=True)
        while True:
            try:
                if open({str(pidfile)!r}).read():
                    break
            except OSError:
                pass
            time.sleep(0.1)
        time.sleep(0.5)  # the reaper has seen the actor
        """)], cwd=ROOT)
    assert driver.wait(timeout=120) == 0
    name = pidfile.read_text()
    end = time.monotonic() + 60
    while _exists(name) and time.monotonic() < end:  # a bound on waiting, not a timing assertion
        time.sleep(0.2)
    assert not _exists(name), "the dead driver's actor left its segment"


def test_a_segment_is_created_once_per_name_and_attached_only_while_it_exists():
    s = create_segment(128)
    try:
        with pytest.raises(FileExistsError):
            Segment(s.name, create=True, size=128)
        with pytest.raises(ValueError, match="positive size"):
            Segment(s.name + "x", create=True, size=0)
        m = attach(s.name)
        m.buf[:3] = b"abc"
        assert bytes(s.buf[:3]) == b"abc" and m.size == 128
        m.close()
    finally:
        s.close()
        s.unlink()
    with pytest.raises(FileNotFoundError):
        attach(s.name)
