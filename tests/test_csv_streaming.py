"""Reading a CSV log row by row into packed arrays (issue 25: a 2-million-row log held every row as text, 1.5 GB
for a 60 MB file).  Correctness here, against the arrays the log was written from; the memory is measured in
the commit that made the change, not asserted (a machine-dependent number)."""

from __future__ import annotations

import numpy as np
import pytest

from delaykit.identify.flightlog import FlightLog, LogError, iter_csv_rows, read_csv_rows
from delaykit.identify.iodata import read_experiment


def _write(path, n, seed=0, note=False):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    z = rng.normal(size=n)
    zr = (t >= 0.5 * t[-1]).astype(float)
    seq = np.arange(n) + 7
    head = "t,z,z_ref,seq" + (",note" if note else "")
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(head + "\r\n")
        for i in range(n):
            fh.write(f"{float(t[i])!r},{float(z[i])!r},{zr[i]:g},{seq[i]}" + (f",n{i % 3}" if note else "") + "\r\n")
            if i == n // 3:
                fh.write("\r\n")  # a blank line: skipped, and the line numbers go on counting
    return t, z, zr, seq


def test_a_generated_log_reads_back_exactly(tmp_path):
    # repr() of a float reads back to the same float: the arrays must be equal bit for bit
    p = tmp_path / "big.csv"
    t, z, zr, seq = _write(p, 50_000)
    log = FlightLog.from_csv(p)
    assert np.array_equal(log.t, t) and np.array_equal(log.z, z) and np.array_equal(log.z_ref, zr)
    assert set(log.extra) == {"seq"} and np.array_equal(log.extra["seq"], seq)
    exp = read_experiment(p, time="t", outputs=["z"], input="z_ref")
    assert np.array_equal(exp.t, t) and np.array_equal(exp.outputs["z"], z)


def test_a_text_column_is_kept_as_text(tmp_path):
    p = tmp_path / "note.csv"
    t, *_ = _write(p, 100, note=True)
    log = FlightLog.from_csv(p)
    assert log.extra["note"] == [f"n{i % 3}" for i in range(100)] and list(log.extra) == ["seq", "note"]


def test_rows_stream_with_their_line_numbers(tmp_path):
    p = tmp_path / "s.csv"
    _write(p, 10)
    header, rows = iter_csv_rows(p)
    assert header == ["t", "z", "z_ref", "seq"]
    first = next(rows)
    assert first[1] == 2 and first[0][3] == "7"
    lines = [line for _, line in rows]
    assert lines == [3, 4, 5] + list(range(7, 13))  # line 6 is the blank one
    assert read_csv_rows(p)[1][-1][1] == 12


def test_a_bad_byte_late_in_the_file_is_named(tmp_path):
    p = tmp_path / "bad.csv"
    _write(p, 1000)
    data = bytearray(p.read_bytes())
    at = len(data) - 5
    data[at] = 0xFF
    p.write_bytes(bytes(data))
    with pytest.raises(LogError, match=rf"not a UTF-8 text CSV \(byte {at} is 0xff\)"):
        FlightLog.from_csv(p)
    data[at] = 0
    p.write_bytes(bytes(data))
    with pytest.raises(LogError, match=rf"NUL bytes at byte {at}"):
        FlightLog.from_csv(p)
