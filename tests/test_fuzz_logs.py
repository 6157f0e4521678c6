"""Damaged flight logs: truncated, overwritten, random, empty or mislabelled ULog, DataFlash and tlog files.

The promise: reading one raises :class:`~delaykit.identify.flightlog.LogError` (one line naming the file and the
problem) or, where the damage cannot be seen (a file cut exactly between two messages, a changed value inside a
message of a format without checksums), returns what the file holds: for a cut, exactly the first samples of the
whole file's read.  Never another exception, never a traceback on the command line.

The real logs are read from ../shared/data (tests/shared_data.py) and damaged in temporary copies; the tlog is
written by pymavlink (tests/test_vehicle_logs.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from delaykit.cli import app
from delaykit.identify.flightlog import LogError
from delaykit.identify.vehiclelogs import list_log, read_signals

from shared_data import data_path
from test_vehicle_logs import write_tlog

SETTINGS = settings(max_examples=12, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
# (the file, the signal read from it)
REAL = {
    "ulog": (("px4-ulog", "vtol_hop.ulg"), "-vehicle_local_position.z"),
    "dataflash": (("ardupilot-dataflash", "copter_3.6.4_takeoff_land.bin"), "CTUN.CRt"),
}
TLOG_SIGNAL = "-LOCAL_POSITION_NED.vz"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """The bytes, suffix, signal and whole read of each log: the two real ones (where present) and a tlog."""
    out = {}
    tmp = tmp_path_factory.mktemp("logs")
    p = tmp / "flight.tlog"
    write_tlog(p)
    out["tlog"] = (p.read_bytes(), ".tlog", TLOG_SIGNAL, read_signals(p, [TLOG_SIGNAL])[TLOG_SIGNAL])
    for kind, (parts, spec) in REAL.items():
        from shared_data import have_data

        if have_data(*parts):
            path = data_path(*parts)
            out[kind] = (path.read_bytes(), path.suffix, spec, read_signals(path, [spec])[spec])
    return out


def _log(logs, kind):
    if kind not in logs:
        data_path(*REAL[kind][0])  # skips, saying which file is absent
    return logs[kind]


def outcome(path, spec, whole, **kw):
    """Read ``spec`` from a damaged file: "error" for a LogError, else check the samples against the whole read."""
    try:
        sig = read_signals(path, [spec], **kw)[spec]
    except LogError as exc:
        assert "\n" not in str(exc) and str(path.name) in str(exc)
        return "error"
    return sig


def assert_prefix(sig, whole):
    n = sig.t.size
    assert 0 < n <= whole.t.size
    np.testing.assert_array_equal(sig.t, whole.t[:n])
    np.testing.assert_array_equal(sig.values, whole.values[:n])


@pytest.mark.parametrize("kind", ["ulog", "dataflash", "tlog"])
@pytest.mark.parametrize("fraction", [0.0, 1e-5, 0.01, 0.3, 0.5, 0.77, 0.999])
def test_truncated_is_an_error_or_a_prefix(logs, kind, fraction, tmp_path):
    data, suffix, spec, whole = _log(logs, kind)
    n = int(fraction * len(data))
    p = tmp_path / f"cut{suffix}"
    p.write_bytes(data[:n])
    got = outcome(p, spec, whole)
    if got != "error":  # (cut exactly between two messages: a shorter whole log)
        assert_prefix(got, whole)
    # with allow_truncated: what the file holds up to its last whole message, or an error if the signal is not there
    got = outcome(p, spec, whole, allow_truncated=True)
    if got != "error":
        assert_prefix(got, whole)
    elif n > 0.5 * len(data):
        pytest.fail(f"{kind} cut at {n} of {len(data)} bytes: allow_truncated should read its first half")


@pytest.mark.parametrize("kind", ["ulog", "dataflash", "tlog"])
def test_cut_inside_the_last_message_is_refused(logs, kind, tmp_path):
    data, suffix, spec, whole = _log(logs, kind)
    p = tmp_path / f"cut{suffix}"
    p.write_bytes(data[:-1])
    with pytest.raises(LogError, match="cut short"):
        read_signals(p, [spec])
    with pytest.raises(LogError, match="cut short"):
        list_log(p)
    assert_prefix(read_signals(p, [spec], allow_truncated=True)[spec], whole)


@pytest.mark.parametrize("kind", ["ulog", "dataflash", "tlog"])
@SETTINGS
@given(data=st.data())
def test_truncated_anywhere(logs, kind, data, tmp_path_factory):
    raw, suffix, spec, whole = _log(logs, kind)
    n = data.draw(st.integers(0, len(raw)))
    p = tmp_path_factory.mktemp("cut") / f"cut{suffix}"
    p.write_bytes(raw[:n])
    for kw in ({}, {"allow_truncated": True}):
        got = outcome(p, spec, whole, **kw)
        if got != "error":
            assert_prefix(got, whole)


@pytest.mark.parametrize("kind", ["ulog", "dataflash", "tlog"])
@SETTINGS
@given(data=st.data())
def test_overwritten_bytes(logs, kind, data, tmp_path_factory):
    raw, suffix, spec, whole = _log(logs, kind)
    at = data.draw(st.integers(0, len(raw) - 1))
    junk = data.draw(st.binary(min_size=1, max_size=64))
    damaged = bytearray(raw)
    damaged[at:at + len(junk)] = junk
    damaged = bytes(damaged[:len(raw)])
    p = tmp_path_factory.mktemp("junk") / f"junk{suffix}"
    p.write_bytes(damaged)
    got = outcome(p, spec, whole)
    if got != "error" and kind == "tlog":
        # MAVLink packets carry checksums: a tlog read without error holds the same samples (damage in the stamps
        # or in other fields may pass)
        assert got.t.size == whole.t.size


@pytest.mark.parametrize("suffix", [".ulg", ".bin", ".log", ".tlog"])
@pytest.mark.parametrize("content", [b"", b"\x00", bytes(np.random.default_rng(0).integers(0, 256, 5000, np.uint8)),
                                     b"t,u,z\n0,0,0\n1,1,0\n2,1,1\n", b"ULog\x01\x12\x35\x01" + bytes(8),
                                     b"\xa3\x95\x80" + bytes(86)])
def test_random_empty_and_mislabelled_files(suffix, content, tmp_path):
    p = tmp_path / f"x{suffix}"
    p.write_bytes(content)
    with pytest.raises(LogError) as info:
        read_signals(p, ["vehicle_local_position.z"])
    assert "\n" not in str(info.value) and "x" + suffix in str(info.value)
    try:
        listing = list_log(p)
    except LogError:
        pass
    else:  # a bare header of the right format is a log with nothing in it
        assert (suffix == ".ulg" and content.startswith(b"ULog")
                or suffix in (".bin", ".log") and content.startswith(b"\xa3\x95"))
        assert listing.topics == ()
    if not content:
        assert "empty" in str(info.value)


def test_the_command_line_says_one_line(logs, tmp_path):
    runner = CliRunner()
    data, suffix, spec, whole = logs["tlog"]
    p = tmp_path / "cut.tlog"
    p.write_bytes(data[: len(data) // 2 + 3])
    for args in (["log", str(p)], ["log", str(p), "--json"],
                 ["identify", str(p), "--input=-POSITION_TARGET_LOCAL_NED.vz", "--output=-LOCAL_POSITION_NED.vz"],
                 ["estimate", str(p), "--kp", "1", "--output=-LOCAL_POSITION_NED.z",
                  "--reference=-POSITION_TARGET_LOCAL_NED.z"]):
        r = runner.invoke(app, args)
        assert r.exit_code == 2, (args, r.output)
        assert r.output.startswith("error: ") and r.output.count("\n") == 1 and "cut short" in r.output
    r = runner.invoke(app, ["log", str(p), "--allow-truncated", "--json"])
    assert r.exit_code == 0, r.output


@SETTINGS
@given(spec=st.one_of(st.text(max_size=40),
                      st.from_regex(r"-?[A-Za-z_]{1,25}(\[[0-9]{1,2}\])?\.[A-Za-z_]{1,12}(\[[0-9]{1,2}\])?(\*[0-9.e-]{1,6})?",
                                    fullmatch=True)))
def test_any_signal_name(logs, spec, tmp_path_factory):
    data, suffix, _, _ = logs["tlog"]
    p = tmp_path_factory.mktemp("spec") / "flight.tlog"
    p.write_bytes(data)
    try:
        sig = read_signals(p, [spec])
    except LogError as exc:
        assert "\n" not in str(exc)
    else:
        assert np.all(np.diff(sig[spec].t) > 0)
