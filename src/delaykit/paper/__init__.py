"""Paper: Armah & Yi's published numbers, and everything that regenerates or extends the paper from them.

:mod:`.data` keeps the printed tables verbatim (as claims to check) with delaykit's converged counterparts,
:mod:`.report` writes Table 1's report, :mod:`.reproduce` regenerates every table and figure with a verdict for
each, and :mod:`.demo` runs the whole flow (fly, estimate, design, fly again) on the emulator. This layer uses all
those below it. The names are re-exported lazily, on first use, so that importing :mod:`.data` (as the command line
does) does not import matplotlib or the hardware layer.
"""

from .._lazy import by_module, lazy_exports

_SOURCES = {
    "data": ["TABLE1", "TABLE2", "TABLE3", "TABLE1_KP", "Table1Row", "Table3Row", "table1", "table3", "paper_loop"],
    "report": ["Report", "write_report", "table1_verdict", "table1_markdown", "plot_table1_responses"],
    "reproduce": ["Item", "Reproduction", "reproduce", "TABLE4"],
    "demo": ["DemoReport", "run_demo"],
}

__all__ = [name for names in _SOURCES.values() for name in names]


__getattr__, __dir__ = lazy_exports(__name__, by_module(_SOURCES), globals())
