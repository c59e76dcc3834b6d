"""Identifying devices: a Pioneer behind a pyserial URL (as MobileSim serves one), a camera from its
frames, and what is said when nothing answers."""

from __future__ import annotations

import socket
import threading

import cv2
import numpy as np
import pytest

from onboard.emulators.pioneer import PioneerEmulator, PioneerEmulatorConfig, PioneerServerState
from onboard.emulators.tcp import TcpPort
from onboard.probe import describe, identify_camera, identify_port


@pytest.mark.integration
def test_a_pioneer_behind_a_url_is_identified(room_base):
    config = PioneerEmulatorConfig(name="MobileSim", subtype="p3dx-sh")
    with PioneerEmulator(PioneerServerState(room_base(), config), TcpPort()) as emulator:
        answer = identify_port(emulator.path)
    assert answer == {"device": "pioneer", "name": "MobileSim", "type": "Pioneer", "subtype": "p3dx-sh",
                      "port": emulator.path}
    assert describe(answer) == f"{emulator.path}: Pioneer MobileSim Pioneer p3dx-sh"


def test_a_camera_is_identified_by_its_frames(tmp_path):
    for i in range(2):
        cv2.imwrite(str(tmp_path / f"frame_{i:02d}.png"), np.zeros((480, 1280, 3), np.uint8))
    answer = identify_camera(str(tmp_path / "frame_%02d.png"))
    assert (answer["device"], answer["width_px"], answer["height_px"]) == ("camera", 1280, 480)
    assert describe(answer).startswith(f"{tmp_path}/frame_%02d.png: camera 1280x480")


def test_nothing_answering_is_said_with_each_attempt(tmp_path):
    answer = identify_port("socket://127.0.0.1:9")  # discard: nobody listens
    assert answer["device"] == "unknown" and "pioneer: " in answer["error"] and "ptu-d46: " in answer["error"]
    missing = identify_camera(str(tmp_path / "video9"))
    assert missing["device"] == "unknown" and "cannot be opened" in missing["error"]
    assert describe(missing).startswith(f"{tmp_path / 'video9'}: nothing identified (")


def test_a_port_that_hangs_up_at_once_is_reported_not_raised():
    """pyserial's own error, from a Pioneer handshake cut off, escaped and ended the whole probe."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        hang_up = threading.Thread(target=lambda: [server.accept()[0].close() for _ in range(2)], daemon=True)
        hang_up.start()
        answer = identify_port(f"socket://127.0.0.1:{port}")
    assert answer["device"] == "unknown" and "pioneer: " in answer["error"]


@pytest.mark.parametrize("port", ["", " "])
def test_an_empty_port_is_refused_not_taken_for_every_port(capsys, port):
    """`--port ""` (an unset variable in a script) probed every port and exited 0."""
    from onboard.cli import run_probe

    with pytest.raises(SystemExit) as exit_:
        run_probe(["--port", port])
    assert exit_.value.code == 2 and "--port: empty" in capsys.readouterr().err
