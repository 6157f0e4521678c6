"""The verification page's Table 1 is the program's: each row recomputed by ``delaykit.paper.data.table1`` (the
exact simulator that ``delaykit reproduce`` runs) must print as the page shows it, so a kernel change that moves a
number makes this fail until the page is regenerated from ``delaykit reproduce``'s ``report.md``."""

from __future__ import annotations

from pathlib import Path

PAGE = Path(__file__).resolve().parents[1] / "docs" / "verification.md"


def _page_rows() -> list[list[str]]:
    lines = PAGE.read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| K | Td = K"))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows


def test_table1_on_the_verification_page_is_what_reproduce_computes_now():
    from delaykit.paper.data import table1

    want = [[f"{r.K:.4f}", f"{r.delay:.5f}", f"{r.paper_overshoot:.3f}", f"{r.overshoot:.4f}", f"{r.difference:+.4f}",
             "–" if r.equivalent_delay is None else f"{r.equivalent_delay:.5f}"] for r in table1()]
    assert len(want) == 7  # the paper's seven rows (a guard against reading an empty table)
    assert _page_rows() == want
