"""syt-onboard make-certs: the files, their modes, what the certificates say, and configs Zenoh accepts."""

from __future__ import annotations

import ipaddress
import stat

import zenoh
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID

from onboard.certificates import Issued
from onboard.cli import main

STEMS = ("ca", "robot", "planner", "observer")


def test_make_certs_writes_a_ca_the_robot_and_each_role(tmp_path, capsys):
    out = tmp_path / "certs"
    assert main(["make-certs", "--out", str(out), "--host", "robot.local", "--host", "10.0.0.5"]) == 0
    printed = capsys.readouterr().out.split()
    assert str(out / "zenoh-robot.json5") in printed and str(out / "robot.pem") in printed
    for stem in STEMS:
        assert stat.S_IMODE((out / f"{stem}.key").stat().st_mode) == 0o600, stem
    ca = Issued.read(out, "ca")
    for stem in ("robot", "planner", "observer"):
        issued = Issued.read(out, stem)
        assert issued.common_name == stem
        issued.cert.verify_directly_issued_by(ca.cert)  # raises if another key signed it
    san = Issued.read(out, "robot").cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.DNSName) == ["localhost", "robot.local"]
    assert san.get_values_for_type(x509.IPAddress) == [ipaddress.ip_address("127.0.0.1"),
                                                       ipaddress.ip_address("10.0.0.5")]
    usage = Issued.read(out, "planner").cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert list(usage) == [ExtendedKeyUsageOID.CLIENT_AUTH]


def test_the_configs_name_the_certificates_and_load_in_zenoh(tmp_path):
    out = tmp_path / "certs"
    assert main(["make-certs", "--out", str(out), "--host", "robot.local", "--cert-dir", "/etc/syt/certs"]) == 0
    robot = zenoh.Config.from_file(str(out / "zenoh-robot.json5"))
    assert robot.get_json("transport/link/tls/listen_certificate") == '"/etc/syt/certs/robot.pem"'
    assert robot.get_json("access_control/enabled") == "true"
    for role in ("planner", "observer"):
        client = zenoh.Config.from_file(str(out / f"zenoh-{role}.json5"))
        assert client.get_json("connect/endpoints") == '["tls/robot.local:7447"]'
        assert client.get_json("transport/link/tls/connect_private_key") == f'"/etc/syt/certs/{role}.key"'


def test_an_existing_ca_is_kept_unless_forced(tmp_path, caplog):
    out = tmp_path / "certs"
    assert main(["make-certs", "--out", str(out)]) == 0
    ca = (out / "ca.pem").read_bytes()
    assert main(["make-certs", "--out", str(out)]) == 2
    assert "ca.key exists" in caplog.text and (out / "ca.pem").read_bytes() == ca
    assert main(["make-certs", "--out", str(out), "--force"]) == 0
    assert (out / "ca.pem").read_bytes() != ca


def test_bad_hosts_and_days_are_refused_by_name(tmp_path, caplog):
    assert main(["make-certs", "--out", str(tmp_path / "a"), "--host", "robot/1"]) == 2
    assert "--host 'robot/1'" in caplog.text
    assert main(["make-certs", "--out", str(tmp_path / "b"), "--days", "0"]) == 2
    assert "--days must be 1 to 36500, not 0" in caplog.text
    assert main(["make-certs", "--out", str(tmp_path / "c"), "--days", "4000000"]) == 2  # past the year 9999
    assert "not 4000000" in caplog.text
    assert main(["make-certs", "--out", str(tmp_path / "d"), "--host", "[fe80::1]"]) == 2  # a name no address matches
    assert "without brackets" in caplog.text
    assert not any((tmp_path / name).exists() for name in "abcd")
