"""The truth link between ``syt-onboard emulate`` and a simulated camera: what it answers, and the
errors that name what went wrong."""

from __future__ import annotations

import socket
import threading

import pytest

from onboard.emulators.truth import (Truth, TruthLink, TruthLinkError, TruthServer, WorldPlacement, decode,
                                     placement_from_dict, truth_from_dict)
from onboard.sim.world import load_world
from shared.geometry import Pose2D


def test_the_link_answers_the_world_and_the_current_truth(tmp_path):
    world = load_world("paper-lab").with_start(2.0, 2.0, 0.5)
    placement = WorldPlacement.of(world, "paper-lab")
    truths = iter([Truth(Pose2D(2.0, 2.0, 0.5), 0.1, -0.2, True), Truth(Pose2D(2.5, 2.0, 0.5), 0.0, 0.0, False)])
    server = TruthServer(tmp_path / "truth.sock", placement, lambda: next(truths)).start()
    try:
        link = TruthLink(server.path)
        assert link.placement() == placement
        assert link.placement().load(0.26) == world
        head = link.reading()
        assert (head.pan_rad, head.tilt_rad, head.moving) == (0.1, -0.2, True)
        assert link.true_pose == Pose2D(2.5, 2.0, 0.5)
    finally:
        server.close()
    assert not (tmp_path / "truth.sock").exists()


def test_no_emulator_is_a_clear_device_fault(tmp_path):
    with pytest.raises(TruthLinkError, match=r"truth\.sock: .* \(is syt-onboard emulate running\?\)"):
        TruthLink(str(tmp_path / "truth.sock")).truth()


def test_a_garbled_answer_names_what_is_wrong(tmp_path):
    path = str(tmp_path / "liar.sock")
    listener = socket.socket(socket.AF_UNIX)
    listener.bind(path)
    listener.listen()

    def lie() -> None:
        for answer in (b"not json\n", b'{"x_m": 1}\n', b'{"error": "unknown ask"}\n'):
            client, _ = listener.accept()
            client.recv(100)
            client.sendall(answer)
            client.close()
    liar = threading.Thread(target=lie)
    liar.start()
    link = TruthLink(path)
    for expected in ("not a JSON line", "lacks y_m, heading_rad", "unknown ask"):
        with pytest.raises(TruthLinkError, match=expected):
            link.truth()
    liar.join()
    listener.close()


def test_decoding_refuses_what_is_not_a_truth():
    with pytest.raises(TruthLinkError, match="expected a JSON object"):
        decode(b"[1, 2]\n")
    good = {"x_m": 1.0, "y_m": 0, "heading_rad": 0, "pan_rad": 0, "tilt_rad": 0, "head_moving": False}
    assert truth_from_dict(good).pose.x_m == 1.0
    for key, value in (("x_m", "nan"), ("x_m", "1.5"), ("y_m", True), ("tilt_rad", float("inf")), ("pan_rad", 10**400),
                       ("head_moving", "no"), ("head_moving", 1)):  # "1.5", true and "no" were taken
        with pytest.raises(TruthLinkError, match=f"truth reply's {key} must be"):
            truth_from_dict({**good, key: value})
    with pytest.raises(TruthLinkError, match="lacks pan_rad"):
        truth_from_dict({k: v for k, v in good.items() if k != "pan_rad"})


def test_decoding_refuses_what_is_not_a_placement():
    good = {"world": "/worlds/lab.toml", "start": [1.0, 2.0, 0.0], "target": [3, 2, 0.75, -90]}
    assert placement_from_dict(good) == WorldPlacement("/worlds/lab.toml", (1.0, 2.0, 0.0), (3.0, 2.0, 0.75, -90.0))
    for key, value, says in (("start", [1.0, 2.0], "start must be 3 finite numbers"),  # a TypeError later, unnamed
                             ("target", [1, 2, 3, "4"], "target must be 4 finite numbers"),
                             ("start", [1.0, float("nan"), 0.0], "start must be 3"),
                             ("start", [True, 2.0, 0.0], "start must be 3"),
                             ("world", 7, "world must be a path")):
        with pytest.raises(TruthLinkError, match=f"world reply's {says}"):
            placement_from_dict({**good, key: value})
    with pytest.raises(TruthLinkError, match="world reply lacks target"):
        placement_from_dict({k: v for k, v in good.items() if k != "target"})
