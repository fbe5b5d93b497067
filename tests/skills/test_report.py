"""The skill report never flatters: no gap ratio whose oracle does not beat (a), "no policy succeeded" when none
did, and the floor's failures counted by kind; on constructed results (the report's own functions)."""

from __future__ import annotations

import re

from wresdyn.skills.evaluate import gaps_or_why_not
from wresdyn.skills.report import gap_line, table


def _split(success: dict, mpjpe: dict, falls=0, drifts=0, diverged=0) -> dict:
    """``{policy: metrics(...)}`` of 4 motions with the given mean success and MPJPE [rad] per policy."""
    return {k: {"mean": {"success": s, "failures": round(4 * (1 - s)), "mpjpe": mpjpe[k], "g_mpjpe": 2 * mpjpe[k],
                         "falls": falls, "drifts": drifts, "diverged": diverged, "orientation_error": 0.1,
                         "foot_slip": 0.01, "action_rate": 0.02, "foot_error": 0.01},
                "motions": [{}] * 4}
            for k, s in success.items()}


POLICIES = ("reference", "a_nominal", "b_calibrated", "c_delta_action", "d_oracle")


def _ratios(text: str) -> list[str]:
    return re.findall(r"\d+ %", text)


def test_the_gap_is_quoted_where_the_oracle_beats_a():
    split = _split(dict(zip(POLICIES, (0.0, 0.5, 0.5, 0.25, 0.75))), dict(zip(POLICIES, (0.05, 0.04, 0.03, 0.035,
                                                                                           0.02))))
    g, why = gaps_or_why_not(split)
    assert why == "" and abs(g["b_calibrated"] - 0.5) < 1e-9 and abs(g["c_delta_action"] - 0.25) < 1e-9
    assert gap_line(split) == "(b) **50 %**, (c) **25 %**"


def test_no_gap_ratio_when_no_policy_succeeded():
    split = _split(dict.fromkeys(POLICIES, 0.0), dict(zip(POLICIES, (0.05, 0.04, 0.03, 0.035, 0.02))))
    line = gap_line(split)
    assert line == "no gap ratio: no policy succeeded" and not _ratios(line)
    # the reference playing open loop is no policy: its success does not count
    split["reference"]["mean"]["success"] = 1.0
    assert gap_line(split) == "no gap ratio: no policy succeeded"


def test_no_gap_ratio_when_the_oracle_does_not_beat_a():
    # a lower error than (a) would give a ratio of -100 % for (b); the oracle's error is the higher
    worse = _split(dict(zip(POLICIES, (0.0, 0.5, 0.5, 0.5, 0.5))), dict(zip(POLICIES, (0.05, 0.03, 0.02, 0.03,
                                                                                          0.04))))
    line = gap_line(worse)
    assert line.startswith("no gap ratio: the oracle (d) does not beat (a) on MPJPE (40.0 against 30.0 mrad)")
    assert not _ratios(line)
    assert "g-MPJPE (80.0 against 60.0 mm)" in gap_line(worse, "g_mpjpe")
    # a lower error bought by failing early (fewer steps counted) does not beat (a) either
    early = _split(dict(zip(POLICIES, (0.0, 0.75, 0.5, 0.5, 0.25))), dict(zip(POLICIES, (0.05, 0.04, 0.03, 0.03,
                                                                                           0.02))))
    line = gap_line(early)
    assert "succeeds less (25 % against 75 %)" in line and line.startswith("no gap ratio")
    # an oracle 1 % better than (a) makes no ratio either: (b) 0.5 mrad better than (a) would read 500 %
    close = _split(dict(zip(POLICIES, (0.0, 0.5, 0.5, 0.5, 0.5))), dict(zip(POLICIES, (0.05, 0.0200, 0.0195, 0.02,
                                                                                          0.0199))))
    line = gap_line(close)
    assert line.startswith("no gap ratio: the oracle (d) beats (a) on MPJPE by less than 5 % (19.9 against 20.0")
    assert not _ratios(line.replace("5 %", ""))
    # without the oracle there is nothing to close
    del early["d_oracle"]
    assert gap_line(early) == "no gap ratio: needs (a) and the oracle (d)"


def test_the_floor_table_counts_falls_drifts_and_divergences_apart():
    split = _split({"a_nominal": 0.25}, {"a_nominal": 0.04}, falls=2, drifts=1, diverged=0)
    head, _, row = table(split, floor=True).splitlines()
    cols = [c.strip() for c in head.strip("|").split("|")]
    vals = [c.strip() for c in row.strip("|").split("|")]
    got = dict(zip(cols, vals))
    assert (got["success"], got["falls"], got["drifts"], got["diverged"]) == ("25 % (1/4)", "2", "1", "0")
