"""``syt-onboard probe``: which serial ports and cameras this machine has, and what answers on them.

A serial port (a device path or a pyserial URL such as ``socket://HOST:8101``) is asked first as a
Pioneer (SYNC0/1/2: name, type and subtype from SYNC2, no session opened), then as a PTU-D46
(``ED``, ``FT``, ``V``: its version). A camera is opened through OpenCV and one frame read (its
resolution). The USB vendor, product and serial number of each serial adapter are listed too:
they are what the udev rules in ``deploy/robot/`` match.
"""

from __future__ import annotations

import glob
import logging

from serial.tools import list_ports

from onboard.devices import DeviceFault
from onboard.hardware import pioneer, ptu, uvc_camera

log = logging.getLogger(__name__)


def identify_port(port: str, baud: int = 9600) -> dict:
    """``{"device": "pioneer", "name", "type", "subtype"}``, ``{"device": "ptu-d46", "version"}``, or
    ``{"device": "unknown", "error": ...}`` saying what each attempt met; ``"port"`` in all."""
    problems = []
    for kind, ask in (("pioneer", lambda: pioneer.probe(port, baud, timeout_ms=500)),
                      ("ptu-d46", lambda: ptu.probe(port, baud, timeout_s=2.0))):
        try:
            return {**ask(), "port": port}
        except (DeviceFault, OSError) as exc:  # OSError: pyserial's, a port that hangs up mid-handshake
            log.info("%s is not a %s: %s", port, kind, exc)
            problems.append(f"{kind}: {exc}")
    return {"device": "unknown", "port": port, "error": "; ".join(problems)}


def identify_camera(device: str) -> dict:
    try:
        return uvc_camera.probe(device)
    except DeviceFault as exc:
        return {"device": "unknown", "path": device, "error": str(exc)}


def serial_ports() -> list[dict]:
    """The machine's serial ports with their USB identity (what a udev rule matches)."""
    return [{"port": p.device, "description": p.description,
             "usb": None if p.vid is None else {"vendor": f"{p.vid:04x}", "product": f"{p.pid:04x}",
                                                "serial": p.serial_number}}
            for p in sorted(list_ports.comports(), key=lambda p: p.device)]


def camera_devices() -> list[str]:
    return sorted(glob.glob("/dev/video*"), key=lambda path: (len(path), path))


def probe_all() -> dict:
    """Every serial port and camera, each with what answered on it."""
    return {"serial": [entry | {"answer": identify_port(entry["port"])} for entry in serial_ports()],
            "cameras": [identify_camera(device) for device in camera_devices()]}


def describe(answer: dict) -> str:
    """One line for a person."""
    where = answer.get("port") or answer.get("path")
    kind = answer["device"]
    if kind == "pioneer":
        return f"{where}: Pioneer {answer['name']} {answer['type']} {answer['subtype']}"
    if kind == "ptu-d46":
        return f"{where}: PTU-D46 {answer['version']}"
    if kind == "camera":
        return f"{where}: camera {answer['width_px']}x{answer['height_px']} at {answer['fps']:g} fps"
    return f"{where}: nothing identified ({answer['error']})"
