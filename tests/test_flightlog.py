"""The flight-log reader on files as people save them (spreadsheets, binaries, wrong separators, garbage
values), and fuzzed with hypothesis: only delaykit's own errors may escape."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from delaykit.errors import DelaykitError, InvalidValueError
from delaykit.identify.flightlog import MAX_ALTITUDE, FlightLog, LogError, write_log

# a small log whose step is known by construction: z_ref goes from 0.5 to 1.5 at t = 1.0 (sample 10)
T = np.round(np.arange(0.0, 3.0, 0.1), 10)
COLUMNS = {"t": T, "z": np.full(T.size, 0.5), "z_ref": np.where(T >= 1.0, 1.5, 0.5), "u": np.zeros(T.size)}


def good_text(tmp_path) -> str:
    """The log as write_log writes it (the reader's own format)."""
    write_log(tmp_path / "ref.csv", COLUMNS)
    return (tmp_path / "ref.csv").read_text()


def test_spreadsheet_csv_with_bom_and_crlf_is_read(tmp_path):
    # what "CSV UTF-8" in a spreadsheet saves: a UTF-8 byte-order mark and CRLF line ends
    lines = good_text(tmp_path).splitlines()
    path = tmp_path / "sheet.csv"
    path.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(lines).encode() + b"\r\n")
    log = FlightLog.from_csv(path)
    # the values are those of COLUMNS: step +1 m at t = 1.0 s from 0.5 m, all 30 samples
    assert log.t.size == T.size and log.step_time == pytest.approx(1.0) and log.step == pytest.approx(1.0)
    assert log.z0 == pytest.approx(0.5) and np.allclose(log.u, 0.0)


def test_old_mac_line_ends_are_read_too(tmp_path):
    path = tmp_path / "cr.csv"
    path.write_bytes("\r".join(good_text(tmp_path).splitlines()).encode())
    assert FlightLog.from_csv(path).t.size == T.size  # every row of COLUMNS


def test_binary_file_is_a_clear_error_naming_the_file(tmp_path):
    path = tmp_path / "photo.csv"
    path.write_bytes(bytes(range(256)))  # byte 0x80 (at 128) is not UTF-8; byte 0 is a NUL
    with pytest.raises(LogError, match=r"photo\.csv is not a UTF-8 text CSV") as info:
        FlightLog.from_csv(path)
    assert isinstance(info.value, InvalidValueError)
    path.write_bytes(b"t,z,z_ref\n0,\x00,1\n")  # valid UTF-8, but a NUL: still not a text CSV
    with pytest.raises(LogError, match=r"photo\.csv is not a UTF-8 text CSV \(it holds NUL bytes at byte 12\)"):
        FlightLog.from_csv(path)


@pytest.mark.parametrize("sep, what", [(";", "semicolons"), ("\t", "tabs")])
def test_other_separators_are_refused_saying_it_must_be_a_comma(tmp_path, sep, what):
    path = tmp_path / "semi.csv"
    path.write_text(good_text(tmp_path).replace(",", sep))
    with pytest.raises(LogError, match=rf"semi\.csv: the header .* is separated by {what}; the separator must be a comma"):
        FlightLog.from_csv(path)


@pytest.mark.parametrize("column, value, fragment", [
    ("z", "1e300", r"row 6: z is 1e\+300 m, outside \[-1e\+06, 1e\+06\] m"),
    ("z", "-2e6", r"row 6: z is -2e\+06 m, outside"),
    ("z_ref", "1e300", r"row 6: z_ref is 1e\+300 m, outside"),
    ("u", "1e300", r"row 6: u is 1e\+300 m/s, outside"),
    ("t", "1e300", r"row 6: t is 1e\+300 s, outside \[-1e\+10, 1e\+10\] s"),
    ("z", "nan", r"row 6: z is nan \(NaN or inf\)"),
    ("t", "0.05", r"row 6: time 0\.05 does not increase \(previous row has 0\.3\)"),
])
def test_values_out_of_range_are_caught_up_front_naming_file_column_and_row(tmp_path, column, value, fragment):
    # row 6 of the file is the 5th data row (the header is row 1); MAX_ALTITUDE is 1e6 m, MAX_TIME 1e10 s
    lines = good_text(tmp_path).splitlines()
    header = lines[0].split(",")
    cells = lines[5].split(",")
    cells[header.index(column)] = value
    lines[5] = ",".join(cells)
    path = tmp_path / "huge.csv"
    path.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning on the way
        with pytest.raises(LogError, match=rf"huge\.csv: {fragment}"):
            FlightLog.from_csv(path)


def test_row_numbers_count_blank_lines_and_the_bound_is_inclusive(tmp_path):
    lines = good_text(tmp_path).splitlines()
    lines.insert(2, "")  # a blank line: the bad value below is on file row 8, not the 7th record
    cells = lines[7].split(",")
    cells[1] = "5e6"
    lines[7] = ",".join(cells)
    path = tmp_path / "blank.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match=r"row 8: z is 5e\+06 m"):
        FlightLog.from_csv(path)
    # with skip_bad the row is skipped and counted; exactly MAX_ALTITUDE is still accepted
    assert FlightLog.from_csv(path, skip_bad=True).skipped == 1
    z = np.full(T.size, MAX_ALTITUDE)
    assert FlightLog.from_arrays(T, z, COLUMNS["z_ref"]).z0 == MAX_ALTITUDE
    with pytest.raises(LogError, match=r"<arrays>: row 2: z is -1\.1e\+06 m"):
        FlightLog.from_arrays(T, -1.1 * z, COLUMNS["z_ref"])


# ---- fuzzing: whatever the bytes, only a DelaykitError comes out ------------------------------------------
NAMES = ["t", "z", "z_ref", "u", "vz", "seq", "recv_time", "latency_ms"]  # the columns flight.fly() writes
CELL = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**400), 10**400).map(str),
    st.sampled_from(["", " ", "nan", "-inf", "1e300", "-1e308", "1e-320", "0x10", '"1,5"', '"', "1;2", "\u00e9",
                     "１"]),
    st.text(max_size=5),
)
FIELD = st.one_of(st.sampled_from(NAMES), st.text(max_size=4))
SEP = st.sampled_from([",", ",", ",", ";", "\t"])
EOL = st.sampled_from(["\n", "\r\n", "\r"])


@st.composite
def csv_text(draw) -> bytes:
    header = draw(st.lists(FIELD, min_size=1, max_size=9))
    if draw(st.booleans()):
        header = draw(st.permutations(NAMES[:draw(st.integers(2, len(NAMES)))]))
    sep, eol = draw(SEP), draw(EOL)
    if draw(st.booleans()):  # ragged rows of any cells
        rows = draw(st.lists(st.lists(CELL, min_size=0, max_size=len(header) + 1), max_size=40))
    else:  # full rows of numbers (tiny to 1e308, and now and then nan/inf), so the value checks are reached
        number = st.one_of(st.floats(-1e3, 1e3), st.floats(), st.sampled_from([1e300, -1e300, 1e7])).map(repr)
        rows = draw(st.lists(st.lists(number, min_size=len(header), max_size=len(header)), max_size=40))
    if rows and draw(st.booleans()):  # often a valid increasing time column, so the later checks are reached
        rows = [[f"{0.1 * i:.3f}", *r] for i, r in enumerate(rows)]
    text = eol.join(sep.join(r) for r in [header, *rows]) + eol
    bom = b"\xef\xbb\xbf" if draw(st.booleans()) else b""
    return bom + text.encode("utf-8")


def _read_only_delaykit_errors(path, data: bytes) -> None:
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a leaked RuntimeWarning counts as a failure too
        try:
            log = FlightLog.from_csv(path, min_after=1)
        except DelaykitError:
            return
    # what is accepted is usable: finite samples within the documented bounds, increasing times
    assert np.all(np.isfinite(log.t)) and np.all(np.diff(log.t) > 0)
    assert np.all(np.abs(log.z) <= MAX_ALTITUDE) and np.isfinite(log.z0) and np.isfinite(log.step)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=400))
def test_fuzz_reader_with_random_bytes(tmp_path, data):
    _read_only_delaykit_errors(tmp_path / "fuzz.csv", data)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(csv_text())
def test_fuzz_reader_with_random_csv_shaped_text(tmp_path, data):
    _read_only_delaykit_errors(tmp_path / "fuzz.csv", data)
