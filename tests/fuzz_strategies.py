"""Hypothesis strategies for hostile input: numbers, ranges, text with markup and control characters, paths.

Each strategy gives text as a user would type it on the command line (the command line's values are text); the
numbers also come as floats for the Python API.  Values known to start unbounded work, or to reach a known defect of
another part (a delay far below the loop's time scale), are left out by :func:`known_issue`, which says why: they
are listed, with the part that owns them, in ``KNOWN_ISSUES`` and tested one by one in ``test_fuzz_cli.py``.
"""

from __future__ import annotations

import math
from typing import Any, Optional

from hypothesis import strategies as st

__all__ = ["FLOATS", "INTS", "KNOWN_ISSUES", "NUMBER_TEXT", "PATH_CASES", "RANGE_TEXT", "TEXT", "known_issue",
           "number_from_text", "paths"]

# numbers: 0, tiny, huge, not finite, negative, and what Python reads but a person would not write
_SPECIAL = ["0", "-0", "0.0", "1", "-1", "2", "0.5", "-0.5", "1e-300", "5e-324", "-1e-300", "1e-9", "1e300", "-1e300",
            "1e308", "1e400", "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1_0", "0x10", " 1", "1 ", "١",
            "99999999999999999999", "-99999999999999999999", "1e", "", " ", "+1", ".5", "5."]
FLOATS = st.one_of(st.sampled_from([0.0, -0.0, 5e-324, 1e-300, 1e-9, 0.5, 1.0, 2.0, 1e300, -1.0, -1e300,
                                    math.inf, -math.inf, math.nan]),
                   st.floats(allow_nan=True, allow_infinity=True, width=64))
INTS = st.one_of(st.sampled_from([0, 1, -1, 2, 3, 2**31, -2**31, 2**63, 10**20]), st.integers(-10**6, 10**6))
NUMBER_TEXT = st.one_of(st.sampled_from(_SPECIAL), FLOATS.map(repr), INTS.map(str))

# ranges: START:STOP:N, comma lists, K1:K2, with numbers of the above kinds and counts small or silly
_COUNTS = st.sampled_from(["0", "1", "2", "3", "-1", "1.5", "nan", "inf", "", "x"])
RANGE_TEXT = st.one_of(
    st.builds(lambda a, b, n: f"{a}:{b}:{n}", NUMBER_TEXT, NUMBER_TEXT, _COUNTS),
    st.builds(lambda a, b: f"{a}:{b}", NUMBER_TEXT, NUMBER_TEXT),
    st.lists(NUMBER_TEXT, min_size=1, max_size=4).map(",".join),
    st.sampled_from([":", "::", ":::", ",", ",,", "1,,2", "a:b:c", "1:2:3:4", "table1", "TABLE1", "1;2"]),
)

# text: markup, emoji codes, control characters, other scripts, long
_MARKUP = ["[/]", "[b]", "[bold red]x[/bold red]", "[link=file:///etc/passwd]x[/link]", ":smile:", ":b:", "a:b:c",
           "\\[x]", "[", "]", "{}", "{0}", "%s", "%(x)s", "\x1b[31mred\x1b[0m", "\n", "\r\n", "\t", "\x00", "\x7f",
           "\u2028", "\u202e", "é", "温度", "🙂", "'", '"', "`", "$(echo x)", "-", "--", "--help", "1/s",
           "exp(-s)", "s**999999", "1/(s*(0.05*s+1))", "p", "pv", "pid", "none", "true", "filtered"]
TEXT = st.one_of(st.sampled_from(_MARKUP), NUMBER_TEXT, RANGE_TEXT,
                 st.lists(st.sampled_from(_MARKUP), min_size=1, max_size=3).map("".join),
                 st.text(max_size=12))

# paths: relative to a scratch folder (``{tmp}`` is replaced by it); none of them can be written, except "ok.*"
PATH_CASES = ["", ".", "{tmp}", "{tmp}/no/such/folder/x.csv", "{tmp}/x.bogus", "{tmp}/[/].csv", "{tmp}/:b:.png",
              "{tmp}/a-file/x.csv", "{tmp}/" + "n" * 300 + ".csv", "{tmp}/\x1b[31m.csv", "/dev/null/x.csv",
              "{tmp}/missing.csv", "{tmp}/a-file"]


def paths(tmp: str) -> st.SearchStrategy[str]:
    """Paths of :data:`PATH_CASES` under the scratch folder ``tmp`` (which holds a file named ``a-file``)."""
    return st.sampled_from([p.replace("{tmp}", tmp) for p in PATH_CASES])


def number_from_text(text: str) -> Optional[float]:
    """The number Python reads in ``text`` (``None`` where it reads none), to judge a value as the command will."""
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


# (what, which part owns it, the predicate on (command, option, value text)) -- issue 25's unbounded work and tiny
# delays: left out of the random runs (they take minutes, gigabytes, or crash the process), tested one by one
def _big(text: str, limit: float) -> bool:
    x = number_from_text(text)
    return x is not None and (math.isnan(x) or abs(x) > limit)


def _count(text: str, limit: int) -> bool:
    """A range whose count (or integer span) is above ``limit`` or not a number."""
    parts = text.split(":")
    if len(parts) == 3:
        return _big(parts[2], limit)
    if len(parts) == 2:
        a, b = (number_from_text(p) for p in parts)
        return a is None or b is None or not (math.isfinite(a) and math.isfinite(b)) or abs(b - a) > limit
    return len(text.split(",")) > limit


def _tiny(text: str) -> bool:
    pieces = [p for chunk in text.split(",") for p in chunk.split(":")]
    return any((x := number_from_text(p)) is not None and 0 < abs(x) < 1e-3 for p in pieces)


KNOWN_ISSUES: list[tuple[str, str, Any]] = [
    ("a delay far below the loop's time scale (the method of steps takes pieces no longer than the delay)",
     "kernel", lambda cmd, opt, v: opt in ("--delay", "--delays", "--model-delay", "--output-delay",
                                           "--delay-schedule", "--jitter", "--lag") and _tiny(v)),
    ("unbounded work: a huge or unchecked count of delays, gains, branches or frequencies", "cliin",
     lambda cmd, opt, v: opt in ("--delay", "--delays", "--kp", "--kv", "--branches") and _count(v, 50)),
    ("a branch number beyond what SciPy's lambertw takes", "cliin",
     lambda cmd, opt, v: opt == "--branches" and any(_big(p, 1e6) for c in v.split(",") for p in c.split(":"))),
    ("unbounded work: a huge simulated time, region or frequency range", "cliin",
     lambda cmd, opt, v: opt in ("--t-end", "--duration", "--step-duration", "--hover", "--region", "--wmin",
                                 "--wmax", "--disturbance-time", "--ramp", "--p-steps", "--varying-steps")
     and _big(v, 1e3)),
    ("unbounded work: a tiny sample interval", "cliin",
     lambda cmd, opt, v: opt in ("--dt", "--resample", "--period", "--sample-offset")
     and (x := number_from_text(v)) is not None and 0 < abs(x) < 1e-3),
    ("huge gains: the loop's time scale far below its delay (the kernel's tiny-delay case)", "kernel",
     lambda cmd, opt, v: opt in ("--kp", "--kv", "--ki", "--kd", "--a0", "--a1", "--filter-wn", "--step", "--z0",
                                 "--disturbance", "--overshoot", "--peak-time", "--derivative-filter",
                                 "--tracking-time", "--filter-zeta", "--closed-loop-time", "--gain", "--u-before",
                                 "--u0")
     and _big(v, 1e4) and not _big(v, math.inf)),
]


def known_issue(command: str, option: str, value: str) -> Optional[str]:
    """The known issue (``"owner: what"``) a value of ``option`` would reach in ``command``, or None."""
    for what, owner, hit in KNOWN_ISSUES:
        try:
            if hit(command, option, value):
                return f"{owner}: {what}"
        except (TypeError, ValueError):
            continue
    return None
