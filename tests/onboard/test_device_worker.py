"""The agent's per-device worker: one job at a time, and a fault in a job or its reply never leaves the
device busy for good."""

from __future__ import annotations

import threading

import pytest
from conftest import wait_until

from onboard.agent import DeviceWorker


def _run(worker: DeviceWorker, job) -> None:
    assert worker.try_submit(job), "the device is still busy"


@pytest.mark.parametrize("fault", ["job", "reply"])
def test_a_job_or_a_reply_that_raises_leaves_the_device_free_for_the_next(fault, caplog):
    worker = DeviceWorker("pantilt")
    replied, done = threading.Event(), threading.Event()

    def failing_reply() -> None:
        replied.set()
        raise ConnectionError("the querier went away")

    def failing_job():
        if fault == "job":
            replied.set()
            raise OSError("the serial port is gone")
        return failing_reply

    try:
        _run(worker, failing_job)
        assert replied.wait(2.0)
        assert wait_until(lambda: not worker.busy, 2.0)
        _run(worker, lambda: done.set())
        assert done.wait(2.0)  # the thread lives on and takes the next job
        assert f"pantilt worker: {fault} failed" in caplog.text
    finally:
        worker.close()


def test_the_device_is_free_before_the_reply_goes_out():
    """A planner answered at once sends its next command at once: it must not find the device busy."""
    worker = DeviceWorker("base")
    replying, release = threading.Event(), threading.Event()

    def reply() -> None:
        replying.set()
        release.wait(2.0)
    try:
        _run(worker, lambda: reply)
        assert replying.wait(2.0)
        assert not worker.busy
        release.set()
    finally:
        worker.close()


def test_a_second_job_is_refused_while_the_first_runs():
    worker = DeviceWorker("base")
    release = threading.Event()
    try:
        _run(worker, lambda: release.wait() and None)  # a job returns its reply, here none
        assert worker.busy and not worker.try_submit(lambda: None)
        release.set()
    finally:
        worker.close()


def test_closing_a_worker_stuck_in_a_job_gives_up_and_says_so(monkeypatch, caplog):
    """The job under way has left the queue, so the stop marker always fitted and nothing was said."""
    monkeypatch.setattr(DeviceWorker, "close_timeout_s", 0.2)
    worker, release = DeviceWorker("camera"), threading.Event()
    _run(worker, lambda: release.wait() and None)
    worker.close()
    assert "camera worker: still busy after 0.2 s; left behind" in caplog.text
    release.set()
