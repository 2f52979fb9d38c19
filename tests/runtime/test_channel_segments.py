"""The same-node channel's shared-memory segments (aerodaas.actors.data.channel_slots): a sender and a receiver start
no resource-tracker process (CPython's ``SharedMemory`` starts one per process before 3.13), the bytes one writes are
the bytes the other maps, and a segment nobody maps any more is unlinked by the next segment made on the machine and
by a local run's reaper, never one that a live process maps (whatever its pid says). Real processes, /dev/shm as it
is; other pytest workers sweep concurrently, so each check is made while the process it is about still runs."""
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
    """A fresh interpreter running ``code``; it reads a line from stdin wherever ``code`` waits for the test."""
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)


def _exists(name: str) -> bool:
    return os.path.exists(os.path.join(SHM_DIR, name))


def _end(*procs: subprocess.Popen) -> None:
    for p in procs:
        p.kill()
        p.wait(timeout=60)
    sweep_segments({p.pid for p in procs})


def test_a_sender_and_a_receiver_share_the_bytes_and_start_no_resource_tracker():
    """The sender's slot and a receiver's mapping in two fresh interpreters: the receiver reads what the sender
    wrote, and neither process has a child (a resource tracker would be one)."""
    sender = _python("""
        import sys
        from aerodaas.actors.data.channel_slots import Slot
        s = Slot(640 * 480 * 3)
        s.shm.buf[:5] = b"frame"
        print(s.shm.name, flush=True)
        sys.stdin.readline()
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
    finally:
        _end(sender)


def test_a_segment_nobody_maps_is_swept_and_a_mapped_one_kept_whatever_its_pid():
    """A process that left its segment without unlinking it (as a SIGKILLed actor does) stays alive but unmapped
    it: the next segment made sweeps it. A live process's mapped segment is kept even when the sweep is told its
    pid (a reused pid looks the same) — until it is unmapped."""
    code = """
        import sys
        from aerodaas.actors.data.channel_slots import create_segment
        s = create_segment(4096)
        print(s.name, flush=True)
        sys.stdin.readline()
        {then}
        print("done", flush=True)
        sys.stdin.readline()
        """
    left = _python(code.format(then="s.close()  # unmapped, never unlinked"))
    held = _python(code.format(then="pass"))
    try:
        left_name, held_name = left.stdout.readline().strip(), held.stdout.readline().strip()
        assert _exists(left_name) and _exists(held_name)
        assert sweep_segments({left.pid, held.pid}) == []  # both mapped
        left.stdin.write("\n")
        left.stdin.flush()
        assert left.stdout.readline().strip() == "done"
        mine = create_segment(64)  # sweeps first (or another worker's sweep already did)
        try:
            assert not _exists(left_name) and _exists(held_name) and _exists(mine.name)
        finally:
            mine.close()
            mine.unlink()
        assert held_name not in sweep_segments({held.pid}) and _exists(held_name)
    finally:
        _end(left, held)
    sweep_segments({held.pid})
    assert not _exists(held_name)


def test_the_reaper_unlinks_what_a_dead_driver_left():
    """A 'driver' starts its reaper, makes a segment and dies without unlinking it (SIGKILL, the OOM killer): the
    reaper, which sweeps the segments of the driver and of every process it saw below it once they are gone, unlinks
    it. (That the reaper sees and ends the driver's descendants: tests/cluster/test_reaper.py.)"""
    driver = _python("""
        import os
        from aerodaas.clusters import reaper
        from aerodaas.actors.data.channel_slots import create_segment
        import time
        reaper.start(period_s=0.1, grace_s=0.5)
        s = create_segment(4096)
        for _ in range(600):  # the reaper runs (whether it has looked at this process yet or not, it sweeps)
            if reaper.running_for(os.getpid()):
                break
            time.sleep(0.1)
        time.sleep(1.0)
        print(s.name, flush=True)
        os._exit(0)
        """)
    name = driver.stdout.readline().strip()
    try:
        assert driver.wait(timeout=120) == 0 and name
        for _ in range(600):  # up to 60 s for the reaper to notice, wait its grace and sweep: a bound, not a timing
            if not _exists(name):
                break
            time.sleep(0.1)
        assert not _exists(name), "the dead driver's segment is still there"
    finally:
        _end(driver)


def test_a_segment_is_created_once_per_name_and_attached_only_while_it_exists():
    s = create_segment(128)
    try:
        with pytest.raises(FileExistsError):
            Segment(s.name, create=True, size=128)
        with pytest.raises(ValueError, match="positive size"):
            Segment(s.name[:-1] + "0", create=True, size=0)
        with pytest.raises(ValueError, match="not a channel segment's name"):
            attach("../" + s.name)
        m = attach(s.name)
        m.buf[:3] = b"abc"
        assert bytes(s.buf[:3]) == b"abc" and m.size == 128
        m.close()
    finally:
        s.close()
        s.unlink()
    with pytest.raises(FileNotFoundError):
        attach(s.name)
