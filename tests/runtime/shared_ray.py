"""What a test leaves in the Ray session that the tests of one pytest worker share (``ray_session`` in
tests/conftest.py): the run's named actors (``aerodaas/<run>/...``, docs/architecture.md) still alive and
placement groups not removed, read from Ray's GCS (``ray.util.list_named_actors``, ``ray.util.placement_group_table``:
public API served by the GCS itself; ``ray.util.state.list_actors`` would need Ray's dashboard, which the test session
does not start: one more process per worker, and its fixed port 8265 on a machine where several sessions run)."""
from __future__ import annotations

import time

__all__ = ["session_id", "leftovers", "wait_clean"]


def session_id() -> str | None:
    """Which Ray this process is connected to (the GCS address and this driver's job id: a session shut down and
    started again has another), None when Ray is not initialized in this process."""
    import ray  # lazy: a test module that never uses Ray does not import it

    if not ray.is_initialized():
        return None
    ctx = ray.get_runtime_context()
    return f"{ctx.gcs_address} job {ctx.get_job_id()}"


def leftovers() -> list[str]:
    """The run actors still alive (``namespace/name``) and the placement groups not removed (``pg <id> <state>``)."""
    import ray  # lazy: see session_id

    if not ray.is_initialized():
        return []
    out = [f"{a['namespace']}/{a['name']}" for a in ray.util.list_named_actors(all_namespaces=True)
           if a["name"].startswith("aerodaas/")]
    out += [f"pg {pg_id} {pg.get('state')}" for pg_id, pg in ray.util.placement_group_table().items()
            if pg.get("state") != "REMOVED"]
    return sorted(out)


def wait_clean(known: list[str] = (), limit_s: float = 120.0) -> list[str]:
    """:func:`leftovers` but ``known`` ones, read again until there are none or ``limit_s`` wall seconds passed (a
    killed actor leaves the GCS's table a moment after the run returns; the bound is generous for a loaded
    machine). Returns the last reading: empty when the session is clean."""
    deadline = time.monotonic() + limit_s
    left = [x for x in leftovers() if x not in known]
    while left and time.monotonic() < deadline:
        time.sleep(0.5)
        left = [x for x in leftovers() if x not in known]
    return left
