"""Every computed verdict: the printed paper values give the expected status, and a paper value moved out of
its stated tolerance flips it (and back).  These call the verdict functions on numbers, not the whole
``reproduce`` run."""

from __future__ import annotations

import pytest

from delaykit.design.tuning import filter_analysis, filter_cutoff_verdict
from delaykit.errors import InvalidTypeError, InvalidValueError
from delaykit.paper.data import Table1Row, Table3Row
from delaykit.paper.report import TABLE1_MODEL, Verdict, table1_check, variants_check
from delaykit.paper.reproduce import (PAPER_511_DELAY, Item, design_text_check, fig5_check, section511_check,
                                      section512_check, table3_check, table3_conclusion_check, table4_check)

STATUSES = ("reproduced", "not reproduced", "not checked")


def _ok(v: Verdict, status: str) -> None:
    assert v.status == status, v.text
    assert v.text.startswith(status)
    if status == "reproduced":
        assert not v.text.startswith("not")


# delaykit's numbers, as computed (the simulator and the root finder are not under test here)
DELAY_511 = 0.36864309804166107
ZETA, OMEGA_N = 0.7684174218822357, 1.606916549348715
ROOT_FROM_PRINTED = complex(-1.23474196, 1.0283675909981598)
T_COMPLEX = complex(0.37426187912471104, -0.25072467139980087)
KVS = [0.0, 0.1, 0.3, 0.5, 0.7]
ABSCISSAE = [-1.4234938523831329, -1.9764461951204673, -3.1950547943946463, -1.8407656607877643, -0.8929003159878822]
VARIANTS = {TABLE1_MODEL: 2.2744519300725408, "continuous, no saturation": 2.979532028395049,
            "sampled every 0.065 s, saturated": 4.409132504437241}
FIG5 = ([1.0, 1.31, 1.6, 2.0], [0.0, 2.300000000000235, 6.745614719395188, 12.056689677867482],
        [1.2183891171263306, 0.9042515541484321, 0.8268525678669228, 0.8010502216612986])


def test_verdict_text_must_start_with_status():
    # delaykit's own errors (still ValueError / TypeError), naming the bad value and what was expected
    with pytest.raises(InvalidValueError, match="must start with its status 'reproduced': 'not reproduced: x'"):
        Verdict("reproduced", "not reproduced: x")
    with pytest.raises(InvalidValueError, match="'reproduced qualitatively' is not one of 'reproduced', "
                                                "'not reproduced', 'not checked'"):
        Verdict("reproduced qualitatively", "reproduced qualitatively")  # type: ignore[arg-type]
    with pytest.raises(InvalidTypeError, match="text must be a str, got NoneType None"):
        Verdict("reproduced", None)  # type: ignore[arg-type]
    with pytest.raises(InvalidTypeError, match="status must be a str, got int 1"):
        Verdict(1, "1")  # type: ignore[arg-type]
    assert issubclass(InvalidValueError, ValueError) and issubclass(InvalidTypeError, TypeError)
    assert Verdict("not checked", "not checked: no data").status == "not checked"


def test_section511_printed_value_reproduced():
    v = section511_check(DELAY_511)
    _ok(v, "reproduced")
    assert "<= 0.00050 s" in v.text and "solver error" in v.text


@pytest.mark.parametrize("paper", [PAPER_511_DELAY - 1e-3, PAPER_511_DELAY + 1.5e-3])
def test_section511_moved_paper_value_not_reproduced(paper):
    _ok(section511_check(DELAY_511, paper_delay=paper), "not reproduced")
    # and back: a tolerance that covers the move reproduces it again
    _ok(section511_check(DELAY_511, paper_delay=paper, tolerance=2e-3), "reproduced")


def test_section512_printed_values_reproduced():
    v = section512_check(ZETA, OMEGA_N, ROOT_FROM_PRINTED, T_COMPLEX, 0.3598)
    _ok(v, "reproduced")
    assert "|0.3743 - (0.374)| = 0.0003 s <= 0.0005 s" in v.text
    assert "complex delay" in v.text  # the caveat is kept


@pytest.mark.parametrize("moved", [dict(paper_delay=0.376), dict(paper_delay=0.372), dict(paper_zeta=0.7690),
                                   dict(paper_omega_n=1.6060), dict(paper_root=complex(-1.2360, 1.0284)),
                                   dict(paper_root=complex(-1.2347, 1.0270))])
def test_section512_moved_paper_value_not_reproduced(moved):
    _ok(section512_check(ZETA, OMEGA_N, ROOT_FROM_PRINTED, T_COMPLEX, **moved), "not reproduced")


def test_section512_unrounded_root_is_not_the_printed_one():
    # the printed root follows from the rounded zeta and omega_n, not from the unrounded ones
    unrounded = complex(-1.234782672030438, 1.028344567459834)
    _ok(section512_check(ZETA, OMEGA_N, unrounded, T_COMPLEX), "not reproduced")


def test_table3_conclusion_reproduced_and_flips():
    _ok(table3_conclusion_check(KVS, ABSCISSAE), "reproduced")
    _ok(table3_conclusion_check(KVS, ABSCISSAE, paper_best_kv=0.1), "not reproduced")
    _ok(table3_conclusion_check(KVS, ABSCISSAE, paper_best_kv=0.2), "not checked")
    # a computed abscissa moved next to Kv = 0.3's, within the tolerance: the ordering is no longer decided
    close = list(ABSCISSAE)
    close[1] = ABSCISSAE[2] + 0.004
    _ok(table3_conclusion_check(KVS, close), "not reproduced")
    _ok(table3_conclusion_check(KVS, close, tolerance=0.001), "reproduced")


def _t3(kv, paper, rightmost):
    return Table3Row(kv=kv, paper=paper, rightmost=rightmost, neutral_line=None, printed_is_root=True, rank=1)


def test_table3_rows():
    good = _t3(0.7, complex(-0.89, 7.47), complex(-0.8929003159878822, 7.474965513519907))
    _ok(table3_check([good]), "reproduced")
    assert good.status == "reproduced" and good.verdict.startswith("reproduced") and "0.005" in good.verdict
    moved = _t3(0.7, complex(-0.89, 7.48), good.rightmost)
    _ok(table3_check([good, moved]), "not reproduced")
    assert moved.status == "not reproduced" and moved.verdict.startswith("not reproduced")


def test_table1_check():
    row = Table1Row(K=5.6646, delay=0.368199, paper_overshoot=2.300, overshoot=2.2744519, equivalent_delay=0.36864)
    v = table1_check([row])
    _ok(v, "reproduced")
    assert "0.05 pp" in v.text
    moved = Table1Row(K=5.6646, delay=0.368199, paper_overshoot=2.400, overshoot=2.2744519, equivalent_delay=0.3704)
    _ok(table1_check([moved]), "not reproduced")


def test_report_variants_check():
    v = variants_check(VARIANTS)
    _ok(v, "reproduced")
    assert "0.05 pp" in v.text
    _ok(variants_check(VARIANTS, paper_overshoot=2.36), "not reproduced")  # none within solver error
    _ok(variants_check(VARIANTS, paper_overshoot=2.98), "not reproduced")  # the unsaturated loop fits instead
    _ok(variants_check(VARIANTS, paper_overshoot=2.98, model="continuous, no saturation"), "reproduced")


def test_fig5_check():
    v = fig5_check(*FIG5)
    _ok(v, "reproduced")
    assert "not compared" in v.text and "0.0005" in v.text
    _ok(fig5_check(*FIG5, no_overshoot_kp=1.31), "not reproduced")
    _ok(fig5_check(*FIG5, overshoot_trend=-1), "not reproduced")
    _ok(fig5_check(*FIG5, rise_trend=+1), "not reproduced")
    _ok(fig5_check(*FIG5, no_overshoot_kp=0.5), "not checked")
    kps, mo, tr = FIG5
    _ok(fig5_check(kps, mo, [tr[0], tr[1], tr[1], tr[3]]), "not reproduced")  # a flat step is not "faster"


def test_table4_and_design_text_checks():
    _ok(table4_check("filter, saturation, sampled 0.065 s", (0.2, 0.01, 0.05)), "reproduced")
    _ok(table4_check("filter, saturation, sampled 0.065 s", (0.6, 0.01, 0.05)), "not reproduced")
    _ok(design_text_check(1.5274352893612786e-07, 1.6257544676528042, 6.13374559183721), "not reproduced")
    paper = {"overshoot": 0.0, "settling_time": 1.63, "peak_time": 6.13}
    _ok(design_text_check(1.5274352893612786e-07, 1.6257544676528042, 6.13374559183721, paper=paper), "reproduced")


def test_filter_verdict_uses_paper_cutoff():
    f = filter_analysis()
    assert f.status == "not reproduced" and f.verdict.startswith("not reproduced")
    assert "5.68 rad/s" in f.verdict and "0.0316 rad/s" in f.verdict
    g = filter_analysis(paper_cutoff=24.4)
    assert g.status == "reproduced" and g.verdict.startswith("reproduced")
    assert "24.4 rad/s" in g.verdict and "low-pass -3 dB" in g.verdict and "5.68" not in g.verdict
    assert g.to_dict()["status"] == "reproduced"
    # the band-pass lower edge, 38 (sqrt 2 - 1) = 15.74 rad/s, fits a quoted 15.7; not a quoted 5.68
    assert filter_cutoff_verdict(f.candidates, 15.7)[0] == "reproduced"
    assert filter_cutoff_verdict(f.candidates, 15.7, rtol=0.001)[0] == "not reproduced"
    assert filter_cutoff_verdict({"wn / (2 pi)": 6.0479}, 6.05)[0] == "reproduced"


def test_item_has_status_in_dict():
    v = section511_check(DELAY_511)
    it = Item.from_verdict("section511", "title", v)
    d = it.to_dict()
    assert d["status"] == "reproduced" and d["verdict"] == v.text and d["status"] in STATUSES
