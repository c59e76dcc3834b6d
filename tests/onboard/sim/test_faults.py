"""Faults inside the robot: a device that raises gets a ``device`` error, the base stops, the agent
serves on. The agent is a real process; the faults are injected in its simulator (``sim/fault``)."""

from __future__ import annotations

import threading
import time

import msgpack
import pytest
import zenoh
from conftest import running_agent, wait_until

from offboard.robot.robot_client import CommandError
from shared import messages as m
from shared.codec import decode, encode
from shared.rpc import request

pytestmark = pytest.mark.integration


def _inject(robot, device: str, after_s: float = 0.0) -> None:
    request(robot.session, robot.keys.sim_fault, m.SimFault(f"fault-{device}", device, after_s), m.SimTruth, 5.0)


def _odometry_times(robot, seconds: float) -> list[float]:
    with robot.session.declare_subscriber(robot.keys.odometry, zenoh.handlers.FifoChannel(64)) as sub:
        time.sleep(seconds)
        samples = []
        while (s := sub.try_recv()) is not None:
            samples.append(decode(s.payload.to_bytes(), m.Odometry).robot_time_s)
    return samples


def test_a_base_that_fails_mid_move_is_stopped_and_the_agent_serves_on(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), "--start", "0.5,1.0,0", "--realtime") as (_, robot):
        _inject(robot, "base", after_s=0.6)
        with pytest.raises(CommandError) as err:
            robot.move(distance_m=4.0, speed_m_s=0.5)
        assert err.value.code == "device" and "injected fault" in str(err.value)
        stopped_at = robot.sim_truth().x_m
        assert 0.5 + 0.02 < stopped_at < 0.5 + 0.5  # it drove, and not far
        assert not robot.state().base_moving
        odometry = _odometry_times(robot, 0.5)
        assert len(odometry) >= 3  # 10 Hz goes on
        assert robot.sim_truth().x_m == pytest.approx(stopped_at, abs=1e-9)  # the wheels did stop
        assert robot.move(distance_m=0.2).status == "done"  # the next move is served
    assert "stopping the base: base fault" in (tmp_path / "onboard.log").read_text()


def test_a_failing_head_or_camera_is_answered_and_the_base_stops(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), "--start", "0.5,1.0,0", "--realtime") as (_, robot):
        results = []
        mover = threading.Thread(target=lambda: results.append(robot.move(distance_m=4.0, speed_m_s=0.3)))
        mover.start()
        assert wait_until(lambda: robot.state().base_moving, 5.0)
        _inject(robot, "pantilt", after_s=0.1)
        with pytest.raises(CommandError) as err:
            robot.look(40.0, 0.0)
        assert err.value.code == "device" and "pantilt" in str(err.value)
        mover.join(5.0)
        assert results[0].status == "stopped" and results[0].distance_m < 1.0  # the base stopped too
        # the halted head's runaway slew ends at its next step: on a loaded machine, a little after the reply
        assert wait_until(lambda: not (s := robot.state()).base_moving and not s.pantilt_moving, 1.0)
        assert 0.0 < robot.state().pan_deg < 40.0
        _inject(robot, "camera")
        with pytest.raises(CommandError, match="camera"):
            robot.capture()
        assert robot.capture().left.shape == (480, 640, 3)  # one fault, then the camera serves again
        assert robot.look(10.0, 0.0).pan_deg == pytest.approx(10.0)


def test_a_fault_for_an_unknown_device_is_refused_naming_the_field(sim_agent):
    """Sent as another build might send it: this side's encoder refuses the option itself."""
    _, robot = sim_agent
    envelope = msgpack.unpackb(encode(m.SimFault("fault-gripper", "camera", 0.0)))
    envelope["body"]["device"] = "gripper"
    (reply,) = robot.session.get(robot.keys.sim_fault, payload=msgpack.packb(envelope), timeout=5.0)
    error = decode(reply.err.payload.to_bytes(), m.ErrorReply)
    assert error.code == "protocol" and "device" in error.message
