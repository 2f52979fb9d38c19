"""A cloud executor sets its analytics up on every thread before its first task (actors/cloud/executor.py
``_prepare_threads``): the run's first frame no longer waits for an ONNX session to open (6 s once, beside two CPU
burners), and an analytics whose set-up fails stops the executor from starting instead of failing each task."""
from __future__ import annotations

import asyncio
import threading

import cv2
import numpy as np
import pytest

from aerodaas.actors.cloud.executor import CloudExecutor
from aerodaas.analytics.core import Analytics


class SetupCounter(Analytics):
    """Records the thread of each ``setup()`` of its copies (a class attribute: the bank deep-copies instances)."""

    name = "counter"
    setups: list[int] = []
    fail = False

    def setup(self) -> None:
        if type(self).fail:
            raise RuntimeError("model file missing")
        type(self).setups.append(threading.get_ident())

    def process(self, frame, meta):
        return [int(frame.shape[0])]


@pytest.fixture(autouse=True)
def _fresh():
    SetupCounter.setups, SetupCounter.fail = [], False
    yield


def test_every_thread_is_set_up_before_the_first_task_and_not_again():
    ex = CloudExecutor("c", mode="real", threads=3, analytics={"m": SetupCounter()})
    assert len(SetupCounter.setups) == 3 and len(set(SetupCounter.setups)) == 3  # one copy per pool thread

    async def one_task():
        await ex.submit("client", [{"k": 1, "model": "m", "sent": 0.0, "up_ms": 0.0, "down_ms": 0.0, "exec_ms": None,
                                    "admit_by": None, "meta": None,
                                    "jpeg": cv2.imencode(".jpg", np.zeros((8, 6, 3), np.uint8))[1].tobytes()}])
        return await ex.collect("client", max_wait_s=30.0)

    replies = asyncio.run(one_task())
    assert [(r["ok"], r["result"]) for r in replies] == [(True, [8])], replies
    assert len(SetupCounter.setups) == 3  # the task used a prepared copy


def test_a_failing_setup_stops_the_executor_from_starting():
    SetupCounter.fail = True
    with pytest.raises(RuntimeError, match="model file missing"):
        CloudExecutor("c", mode="real", threads=2, analytics={"m": SetupCounter()})
