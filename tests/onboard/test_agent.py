"""The onboard agent as a real subprocess, driven through a real Zenoh session on loopback."""

from __future__ import annotations

import ctypes
import math
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import msgpack
import numpy as np
import pytest
import zenoh

from conftest import client_transport, running_agent, wait_until
from offboard.robot.robot_client import CommandError
from shared import messages as m
from shared.codec import decode, encode
from shared.keys import RobotKeys
from shared.rpc import request
from shared.strict import StructureError

pytestmark = pytest.mark.integration


def test_info_describes_the_robot(sim_agent):
    _, robot = sim_agent
    info = robot.info()
    assert info.backend == "sim" and info.robot_id == "syt"
    assert (info.pantilt.pan_max_deg, info.pantilt.tilt_min_deg, info.pantilt.tilt_max_deg) == (159.0, -47.0, 31.0)
    assert info.intrinsics.width_px == 640 and info.mount.baseline_m == pytest.approx(0.12)


def test_move_look_capture(sim_agent):
    _, robot = sim_agent
    before = robot.state()
    result = robot.move(turn_deg=0.0, distance_m=0.5)
    assert result.status == "done" and result.distance_m == pytest.approx(0.5, abs=1e-6)
    moved = math.hypot(result.pose.x_m - before.pose.x_m, result.pose.y_m - before.pose.y_m)
    assert moved == pytest.approx(0.5, abs=0.05)  # odometry: a few percent of noise
    assert result.robot_time_s > before.robot_time_s + result.duration_s * 0.99
    look = robot.look(30.0, 10.0)
    assert (look.pan_deg, look.tilt_deg) == pytest.approx((30.0, 10.0))
    assert look.duration_s == pytest.approx(robot.info().pantilt.slew_time_s(30.0, 10.0), rel=0.05)
    capture = robot.capture()
    assert capture.left.shape == capture.right.shape == (480, 640, 3)
    assert (capture.pan_deg, capture.tilt_deg) == pytest.approx((30.0, 10.0))
    assert capture.pose == result.pose and capture.robot_time_s >= look.robot_time_s
    assert not np.array_equal(capture.left, capture.right)  # two viewpoints
    png = robot.capture("png")
    assert np.array_equal(png.left, capture.left)  # lossless either way
    robot.look(0.0, 0.0)


def test_waypoint_and_stop(sim_agent):
    _, robot = sim_agent
    start = robot.state().pose
    goal = (start.x_m + 0.5, start.y_m + 0.5)
    result = robot.move_to(*goal)
    assert result.status == "done"
    assert math.hypot(result.pose.x_m - goal[0], result.pose.y_m - goal[1]) < 0.02  # odometry reaches it
    stop = robot.stop()
    assert stop.pose == robot.state().pose and not robot.state().base_moving


def test_a_waypoint_where_the_robot_stands_neither_turns_nor_drives_it(sim_agent):
    _, robot = sim_agent
    robot.move(turn_deg=40.0)  # a heading the old code turned back from: by −heading, towards nothing
    before = robot.state().pose
    result = robot.move_to(before.x_m, before.y_m)
    assert result.status == "done" and result.distance_m == 0.0
    assert (result.pose.x_m, result.pose.y_m, result.pose.heading_deg) == \
        pytest.approx((before.x_m, before.y_m, before.heading_deg), abs=1e-6)
    robot.move(turn_deg=-40.0)


@pytest.mark.parametrize("call,code,words", [
    (lambda r: r.look(170.0, 0.0), "limit", "pan limit"),
    (lambda r: r.look(0.0, -60.0), "limit", "tilt limit"),
    (lambda r: r.move(distance_m=50.0), "limit", "max_distance_m"),
    (lambda r: r.move_to(5000.0, 5000.0), "limit", "waypoint_m=[5000.0, 5000.0] is "),  # not "distance_m=", unset
    (lambda r: r.move(distance_m=1.0, speed_m_s=5.0), "limit", "max_speed_m_s"),
])
def test_out_of_range_commands_are_refused_naming_the_limit(sim_agent, call, code, words):
    _, robot = sim_agent
    before = robot.state()
    with pytest.raises(CommandError) as err:
        call(robot)
    assert err.value.code == code and words in str(err.value)
    after = robot.state()  # still serving, and nothing moved
    assert (after.pose, after.pan_deg, after.tilt_deg) == (before.pose, before.pan_deg, before.tilt_deg)


def test_a_waypoint_that_takes_a_turn_past_max_turn_deg_is_refused_as_that_turn_is(tmp_path):
    config = tmp_path / "onboard.toml"
    config.write_text("[base]\nmax_turn_deg = 90\n")
    with running_agent(tmp_path, "--world", "paper-lab", "--config", str(config)) as (_, robot):
        before = robot.state().pose
        heading = math.radians(before.heading_deg)
        with pytest.raises(CommandError) as err:  # 1 m straight behind: a turn of 180°
            robot.move_to(before.x_m - math.cos(heading), before.y_m - math.sin(heading))
        assert err.value.code == "limit" and "°, more than max_turn_deg=90" in str(err.value), str(err.value)
        with pytest.raises(CommandError, match="turn_deg=180 exceeds max_turn_deg=90"):
            robot.move(turn_deg=180.0)
        assert robot.state().pose == before


def _raw_get(session: zenoh.Session, key: str, payload: bytes | None):
    replies = list(session.get(key, payload=payload, timeout=5.0))
    assert len(replies) == 1
    return replies[0]


@pytest.mark.parametrize("payload,field", [
    (b"\x00garbage\xff", "not a msgpack payload"),
    (None, "not a msgpack payload"),  # no payload at all
    (msgpack.packb({"schema": 1, "type": "LookCommand", "body": {"command_id": "k1", "pan_deg": float("nan"), "tilt_deg": 0.0}}), "pan_deg"),
    (msgpack.packb({"schema": 1, "type": "LookCommand", "body": {"command_id": "k2", "pan_deg": 1.0, "tilt_deg": 0.0, "zoom": 3}}), "zoom"),
    (encode(m.StopCommand("k3")), "type"),  # right codec, wrong command for this key
])
def test_malformed_payloads_get_a_protocol_error_and_the_agent_lives_on(sim_agent, payload, field):
    agent, robot = sim_agent
    with client_transport(agent).open() as session:
        reply = _raw_get(session, RobotKeys("syt").look, payload)
        assert reply.ok is None
        error = decode(reply.err.payload.to_bytes(), m.ErrorReply)
    assert error.code == "protocol" and field in error.message
    if payload and b"k1" in payload:
        assert error.command_id == "k1"  # the id is echoed even when the body is bad
    robot.state()  # still answering: a dead or wedged agent raises here
    assert agent.process.poll() is None


def _drain(sub) -> list:
    samples = []
    while (s := sub.try_recv()) is not None:
        samples.append(s)
    return samples


def test_publications_carry_increasing_sequence_numbers(sim_agent):
    agent, _ = sim_agent
    keys = RobotKeys("syt")
    with client_transport(agent).open() as session:
        odometry = session.declare_subscriber(keys.odometry, zenoh.handlers.FifoChannel(64))
        pantilt = session.declare_subscriber(keys.pantilt, zenoh.handlers.FifoChannel(64))
        time.sleep(1.0)
        odo = [decode(s.payload.to_bytes(), m.Odometry) for s in _drain(odometry)]
        head = [decode(s.payload.to_bytes(), m.PanTiltState) for s in _drain(pantilt)]
    assert 5 <= len(odo) <= 15 and 5 <= len(head) <= 15  # 10 Hz for a second
    for stream in (odo, head):
        seqs = [sample.seq for sample in stream]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)


def test_driving_into_a_wall_stalls_at_the_wall(tmp_path, box_world):
    # the box room is 6 m long in x; start 1.5 m from the east wall, heading east
    with running_agent(tmp_path, "--world", str(box_world), "--start", "4.5,1.0,0") as (_, robot):
        result = robot.move(distance_m=3.0)
        truth = robot.sim_truth()
        assert result.status == "stalled" and robot.state().stalled
        assert truth.x_m == pytest.approx(6.0 - robot.info().base.radius_m, abs=0.005)
        assert result.distance_m == pytest.approx(1.5 - robot.info().base.radius_m, abs=0.005)
        assert robot.move(distance_m=-0.5).status == "done"  # backing off works, and clears the stall
        assert not robot.state().stalled


_LOST_PLANNER = textwrap.dedent("""
    import sys, threading
    from offboard.robot.robot_client import RobotClient
    from shared.transport import TransportConfig
    session = TransportConfig(connect=(sys.argv[1],), multicast_scouting=False).open()
    robot = RobotClient(session, "syt")
    robot.wait_for_robot(30.0)
    threading.Thread(target=robot.move, kwargs={"distance_m": 4.0, "speed_m_s": 0.3}, daemon=True).start()
    print("moving", flush=True)
    threading.Event().wait()
""")


def test_driving_into_an_obstacle_stalls_at_its_side(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), "--start", "3.0,1.0,90") as (_, robot):
        assert robot.move(distance_m=3.0).status == "stalled"
        assert robot.sim_truth().y_m == pytest.approx(2.5 - robot.info().base.radius_m, abs=0.005)


def test_teleport_places_the_robot_and_refuses_walls(sim_agent):
    _, robot = sim_agent
    pose = robot.sim_teleport(2.0, 1.0, 45.0)
    assert (pose.x_m, pose.y_m, pose.heading_deg) == pytest.approx((2.0, 1.0, 45.0))
    assert robot.state().pose == pose  # odometry is reset with the truth
    with pytest.raises(CommandError, match="cannot stand"):
        robot.sim_teleport(0.1, 0.1, 0.0)


def test_reset_starts_a_new_run_in_the_same_agent(sim_agent):
    _, robot = sim_agent
    home = (1.7, 4.5, 0.75, -90.0)  # paper-lab's own placement
    view = (4.5, 2.0, 90.0)  # facing the centre table's north side from the south
    pose = robot.sim_reset(view, home, seed=5)
    assert (pose.x_m, pose.y_m, pose.heading_deg) == pytest.approx(view)
    assert robot.state().pose == pose and (robot.state().pan_deg, robot.state().tilt_deg) == (0.0, 0.0)
    without = robot.capture().left
    robot.sim_reset(view, (4.5, 2.5, 0.75, -90.0), seed=5)  # on the centre table, facing the robot
    assert np.abs(robot.capture().left.astype(int) - without).max() > 50  # the target is in view now
    driven = []
    for _ in range(2):  # same seed, same noise: the run repeats exactly
        robot.sim_reset(view, home, seed=5)
        assert np.array_equal(robot.capture().left, without)
        robot.move(turn_deg=-90.0, distance_m=1.0)
        driven.append(robot.state().pose)
    assert driven[0] == driven[1] and driven[0] != robot.sim_truth()
    truth, believed = robot.sim_truth(), robot.state().pose
    with pytest.raises(CommandError, match="overlaps obstacle"):
        robot.sim_reset(view, (4.5, 2.5, 0.5, 0.0), seed=0)  # inside the table
    assert (robot.sim_truth(), robot.state().pose) == (truth, believed)  # a refused reset changes nothing


PACED = ("--start", "0.5,1.0,0", "--realtime")


def test_the_base_stops_when_the_planner_dies_mid_move(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        planner = subprocess.Popen([sys.executable, "-c", _LOST_PLANNER, agent.endpoint],
                                   stdout=subprocess.PIPE, text=True)
        assert planner.stdout.readline().strip() == "moving"
        assert wait_until(lambda: robot.state().base_moving, 5.0)
        time.sleep(0.5)
        planner.kill()
        planner.wait()
        killed = time.monotonic()
        assert wait_until(lambda: not robot.state().base_moving, 3.0, poll_s=0.01)
        assert time.monotonic() - killed < 1.0
        travelled = robot.sim_truth().x_m - 0.5
        assert 0.0 < travelled < 1.5  # far short of the 4 m commanded
        time.sleep(0.5)
        assert robot.sim_truth().x_m - 0.5 == pytest.approx(travelled, abs=1e-6)  # and stays stopped
    assert "planner gone" in (tmp_path / "onboard.log").read_text()


def test_the_watchdog_stops_a_silent_planner(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        robot.close()  # from here on nobody sends heartbeats or holds a planner token
        keys = RobotKeys("syt")
        with client_transport(agent).open() as session:
            odometry = session.declare_subscriber(keys.odometry, zenoh.handlers.RingChannel(1))
            session.get(keys.move, payload=encode(m.MoveCommand("silent", distance_m=4.0, speed_m_s=0.3)), timeout=30.0)
            time.sleep(2.5)  # watchdog is 0.8 s; publications do not count as planner contact
            last = decode(odometry.recv().payload.to_bytes(), m.Odometry)
            assert not last.moving
            assert 0.0 < last.pose.x_m - 0.5 < 0.6
    assert "watchdog: no word from the planner" in (tmp_path / "onboard.log").read_text()


def test_what_is_not_a_heartbeat_on_its_key_does_not_keep_the_robot_moving(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        robot.close()  # nobody sends real heartbeats or holds a planner token
        keys = RobotKeys("syt")
        with client_transport(agent).open() as session:
            odometry = session.declare_subscriber(keys.odometry, zenoh.handlers.RingChannel(1))
            noise = session.declare_publisher(keys.heartbeat)
            session.get(keys.move, payload=encode(m.MoveCommand("noisy", distance_m=4.0, speed_m_s=0.3)), timeout=30.0)
            for _ in range(25):  # 2.5 s of garbage, ten times a second: the watchdog (0.8 s) must still fire
                noise.put(b"\x00not msgpack")
                session.get(keys.capture, payload=b"\x00not a command either", timeout=1.0)  # nor malformed commands
                time.sleep(0.1)
            last = decode(odometry.recv().payload.to_bytes(), m.Odometry)
            assert not last.moving and 0.0 < last.pose.x_m - 0.5 < 0.6
    log_text = (tmp_path / "onboard.log").read_text()
    assert "watchdog: no word from the planner" in log_text
    assert log_text.count("ignoring what is not a heartbeat") == 1  # said once, not 25 times

def test_another_planners_heartbeats_do_not_keep_a_frozen_planners_move_alive(tmp_path, box_world):
    """Planner A froze with its token still held (Zenoh's own threads keep it alive) while planner B
    beats on: B's heartbeats once counted as A's word, and A's move ran its whole course."""
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):  # robot: B, beating
        keys = RobotKeys("syt")
        with client_transport(agent).open() as session:
            token = session.liveliness().declare_token(keys.planner_alive("frozen-a"))
            move = m.MoveCommand("frozen", distance_m=4.0, speed_m_s=0.3)  # 13 s unless stopped
            result = request(session, keys.move, move, m.MoveResult, 30.0, sender="frozen-a")
            token.undeclare()
        assert result.status == "stopped" and 0.0 < result.distance_m < 0.6
        assert robot.move(distance_m=0.1).status == "done"  # B still drives
    assert "watchdog: no word from the planner" in (tmp_path / "onboard.log").read_text()


def test_a_move_from_a_planner_whose_token_is_gone_is_refused(tmp_path, box_world):
    """A move queued before its planner's token vanished once cleared the loss and ran."""
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        keys = RobotKeys("syt")
        log_path = tmp_path / "onboard.log"
        with client_transport(agent).open() as session:
            token = session.liveliness().declare_token(keys.planner_alive("gone-a"))
            assert wait_until(lambda: "planner connected: syt/syt/planner/gone-a" in log_path.read_text(), 5.0)
            token.undeclare()
            assert wait_until(lambda: "planner gone: syt/syt/planner/gone-a" in log_path.read_text(), 5.0)
            with pytest.raises(CommandError) as err:
                request(session, keys.move, m.MoveCommand("late", distance_m=1.0), m.MoveResult, 5.0, sender="gone-a")
        assert err.value.code == "planner" and "gone-a" in str(err.value)
        assert not robot.state().base_moving


def test_a_second_motion_while_moving_is_refused_and_stop_interrupts(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        results = []
        mover = threading.Thread(target=lambda: results.append(robot.move(distance_m=4.0, speed_m_s=0.3)))
        mover.start()
        assert wait_until(lambda: robot.state().base_moving, 5.0)
        with pytest.raises(CommandError) as err:
            robot.move(distance_m=1.0)
        assert err.value.code == "busy"
        robot.stop()
        mover.join(timeout=5.0)
        assert results and results[0].status == "stopped" and results[0].distance_m < 1.0


def test_a_stop_that_cannot_be_read_still_stops_the_robot(tmp_path, box_world):
    """A stop was decoded, and queued behind every other command, before it stopped anything: a
    malformed one, or one that found the queue full, left the robot driving."""
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        results = []
        mover = threading.Thread(target=lambda: results.append(robot.move(distance_m=4.0, speed_m_s=0.3)))
        mover.start()
        assert wait_until(lambda: robot.state().base_moving, 5.0)
        with client_transport(agent).open() as session:
            reply = _raw_get(session, RobotKeys("syt").stop, b"\x00not a stop")
        assert reply.err is not None  # answered as malformed ...
        mover.join(timeout=5.0)
        assert results and results[0].status == "stopped" and results[0].distance_m < 1.0  # ... and acted on
    log_text = (tmp_path / "onboard.log").read_text()  # the watchdog's early stop or the dispatcher's, which come first
    assert "stopping the base: stop asked" in log_text or "stopping the base: malformed stop command" in log_text


def test_sigterm_stops_the_base_and_exits_cleanly(tmp_path, box_world):
    with running_agent(tmp_path, "--world", str(box_world), *PACED) as (agent, robot):
        results = []
        mover = threading.Thread(target=lambda: results.append(robot.move(distance_m=4.0)), daemon=True)
        mover.start()
        assert wait_until(lambda: robot.state().base_moving, 5.0)
        agent.process.send_signal(signal.SIGTERM)
        assert agent.process.wait(timeout=10) == 0
        mover.join(timeout=5.0)
        assert results and results[0].status == "stopped"  # the motion's own reply, sent before it exits
        assert wait_until(lambda: not any(r.ok for r in robot.session.liveliness().get(robot.keys.agent_alive,
                                                                               timeout=0.3)), 5.0)
    assert "agent stopped; base stopped" in (tmp_path / "onboard.log").read_text()


def test_a_command_right_after_a_motion_reply_is_not_refused_as_busy(sim_agent):
    _, robot = sim_agent
    for _ in range(5):  # the base is free by the time its reply arrives
        robot.move(turn_deg=10.0)
        robot.move(turn_deg=-10.0)
        robot.look(5.0, 0.0)
        robot.look(0.0, 0.0)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="tgkill(2) is Linux's")
def test_a_sigterm_that_lands_on_another_thread_still_stops_the_agent(tmp_path):
    """The kernel may hand a process's SIGTERM (its planner's death signal, a ``kill``) to any of its
    threads; here, to one that is not the main thread, which alone runs Python's handlers."""
    tgkill = ctypes.CDLL(None, use_errno=True).tgkill
    with running_agent(tmp_path, "--world", "paper-lab") as (agent, _):
        pid = agent.process.pid
        other = min(int(tid) for tid in os.listdir(f"/proc/{pid}/task") if int(tid) != pid)
        assert tgkill(pid, other, signal.SIGTERM) == 0
        assert wait_until(lambda: agent.process.poll() is not None, 5.0), "the agent went on serving"
    assert agent.process.returncode == 0 and "agent stopped" in agent.log_path.read_text()


def test_a_slow_move_in_real_time_is_waited_for_and_an_absurd_one_refused_by_name(tmp_path):
    with running_agent(tmp_path, "--realtime") as (_, robot):
        # 0.1 m at 0.007 m/s takes 14.3 s; the client once allowed twice what the default speed needs and 10 s
        # (12.3 s) and gave up on a robot still driving
        result = robot.move(distance_m=0.1, speed_m_s=0.007)
        assert result.status == "done" and result.distance_m == pytest.approx(0.1, abs=0.01)
        for absurd in (math.inf, math.nan):
            with pytest.raises(StructureError, match="distance_m"):  # refused where it is made
                robot.move(distance_m=absurd)
            envelope = msgpack.unpackb(encode(m.MoveCommand("absurd", distance_m=1.0)))
            envelope["body"]["distance_m"] = absurd  # ... and by the agent, from a sender that does not check
            (reply,) = robot.session.get(robot.keys.move, payload=msgpack.packb(envelope), timeout=5.0)
            error = decode(reply.err.payload.to_bytes(), m.ErrorReply)
            assert error.code == "protocol" and "distance_m" in error.message


@pytest.mark.parametrize("content", [None, "{ not json5"])
def test_a_bad_zenoh_config_is_named_before_any_device_opens(tmp_path, content):
    path = tmp_path / "zenoh.json5"
    if content is not None:
        path.write_text(content)
    done = subprocess.run([sys.executable, "-m", "onboard.cli", "--backend", "sim", "--zenoh-config", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert str(path) in done.stderr  # a malformed file was refused with Zenoh's message only, no path
    assert "simulated robot" not in done.stderr  # refused before the robot was built


def test_an_agent_whose_session_cannot_open_says_so_and_exits():
    done = subprocess.run([sys.executable, "-m", "onboard.cli", "--backend", "sim", "--listen", "tcp/256.1.1.1:7447",
                           "--no-multicast-scouting"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "cannot open the Zenoh session" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
