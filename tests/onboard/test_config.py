"""Configuration: defaults run, mistakes are refused naming the key."""

import pytest

from onboard.config import OnboardConfig
from shared.config import ConfigError, load_config
from shared.limits import BaseLimits, PanTiltLimits, trapezoid_time_s


def test_no_file_gives_runnable_defaults():
    config = load_config(OnboardConfig)
    assert config.backend == "sim" and config.pantilt.pan_max_deg == 159.0 and config.camera.width_px == 640


def test_file_and_overrides(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text('watchdog_ms = 700\n[base]\nmax_speed_m_s = 0.8\n[sim]\nworld = "office"\n')
    config = load_config(OnboardConfig, path, {"sim.realtime": True})
    assert (config.watchdog_ms, config.base.max_speed_m_s, config.sim.world, config.sim.realtime) == (700, 0.8, "office", True)


@pytest.mark.parametrize("text,key", [
    ("watchdog_ms = 'fast'\n", "watchdog_ms"),
    ("watchdog_ms = 500\n", "watchdog_ms"),  # under three of the planner's 200 ms heartbeats
    ("[base]\nmax_sped_m_s = 1.0\n", "base.max_sped_m_s"),  # a typo is not silently ignored
    ("[base]\ndefault_speed_m_s = 2.0\nmax_speed_m_s = 1.0\n", "base"),
    ("[base]\nmax_speed_m_s = 2.5\n", "base.max_speed_m_s"),  # past the P3-DX firmware's 2200 mm/s
    ("[base]\nmax_turn_rate_deg_s = 600\n", "base.max_turn_rate_deg_s"),  # and its 500°/s
    ("backend = 'serial'\n", "backend"),
    ("[hardware.base]\nport = ''\n", "hardware.base.port"),
    ("[hardware.base]\nbaud = 12\n", "hardware.base.baud"),
    ("[hardware.camera]\ndevise = '/dev/video0'\n", "hardware.camera.devise"),
    ("[sim.odometry_noise]\ndistance_frac = nan\n", "sim.odometry_noise.distance_frac"),
    ("[sim]\nseed = -1\n", "sim.seed"),  # numpy refuses it later, naming nothing
    ("[pantilt\n", "not valid TOML"),
])
def test_mistakes_name_the_file_and_key(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(OnboardConfig, path)
    assert str(path) in str(err.value) and key in str(err.value)


def test_the_hardware_contract_keys(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text('backend = "hardware"\n[hardware.base]\nport = "socket://127.0.0.1:8101"\n'
                    '[hardware.pantilt]\nport = "/dev/ptu"\n[hardware.camera]\ndevice = "sim"\n'
                    'calibration = "stereo.yaml"\n')
    config = load_config(OnboardConfig, path)
    hw = config.hardware
    assert (config.backend, hw.base.port, hw.pantilt.port, hw.camera.device, hw.camera.calibration) == (
        "hardware", "socket://127.0.0.1:8101", "/dev/ptu", "sim", "stereo.yaml")
    assert load_config(OnboardConfig).hardware.base.port == "sim"  # the defaults run without hardware


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(OnboardConfig, tmp_path / "nope.toml")


def test_motion_times_follow_a_trapezoid():
    assert trapezoid_time_s(0.0, 1.0, 1.0) == 0.0
    assert trapezoid_time_s(4.0, 1.0, 1.0) == pytest.approx(5.0)  # 1 s up, 3 s cruise, 1 s down
    assert trapezoid_time_s(0.25, 1.0, 1.0) == pytest.approx(1.0)  # triangle: never reaches top speed
    limits = PanTiltLimits()
    assert limits.slew_time_s(0.0, 0.0) == 0.0
    assert limits.slew_time_s(60.0, 10.0) == pytest.approx(trapezoid_time_s(60.0, 60.0, 300.0) + 0.1)
    assert BaseLimits().drive_time_s(-2.0) == BaseLimits().drive_time_s(2.0) > 2.0 / 0.4


@pytest.mark.parametrize("pan,tilt,limit", [(160.0, 0.0, "pan"), (-159.5, 0.0, "pan"), (0.0, 31.5, "tilt"), (0.0, -48.0, "tilt")])
def test_pan_tilt_limits_name_the_limit(pan, tilt, limit):
    problem = PanTiltLimits().check(pan, tilt)
    assert problem is not None and problem.startswith(f"{limit}_deg=")
    assert PanTiltLimits().check(159.0, -47.0) is None
