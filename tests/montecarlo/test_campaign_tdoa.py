"""``runs.csv`` on a TDoA radio (issue 45): a campaign on ``uwb.mode = "tdoa3"`` reports per run the distance
differences each chaser's (docking) or UAV's (landing) filter accepted and rejected, and for the landing the
mean NIS of the accepted ones; a campaign on two-way ranging has the columns it had (the committed campaigns
under docs/results/ reproduce: tests/montecarlo/test_campaign.py, test_landing_campaign.py).

Each run here is one short run of one policy reduced to its ``runs.csv`` row by the campaign's own task
(``run_one``, what a worker runs), in this process; the campaign writes a row's value of each column
(``swarm.montecarlo.campaign``: ``row[k] for k in columns``), so a row holds exactly its columns.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import pytest

from swarm.core.tdoa_radio import expected_rates
from swarm.landing_scenario import load_landing
from swarm.montecarlo import landing as mc_landing
from swarm.montecarlo.run import FIELDS, TDOA_FIELDS, fields_for, run_one
from swarm.scenario import load_scenario

CUBE = [list(c) for c in itertools.product([-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0])]
"""Eight anchors on a 2 m cube (the paper's four leave differences blind along y: test_docking_tdoa.py)."""
DOCKING_TDOA = {"uwb.mode": "tdoa3", "sim.max_duration_s": 10.0, "anchors_m": CUBE}
LANDING_TDOA = {"uwb.mode": "tdoa3", "vehicle.start_m": [12.0, 3.0, 5.0]}  # a 13-17 s flight
SEED = 123


def test_two_way_ranging_campaigns_keep_their_columns_and_tdoa_ones_add_theirs():
    twr = fields_for(load_scenario("docking"))
    assert not any(k.startswith("tdoa_") for k in twr) and len(twr) == len(FIELDS)
    tdoa = list(fields_for(load_scenario("docking", {"uwb.mode": "tdoa2", "anchors_m": CUBE})))
    at = tdoa.index("accepted_vision") + 1
    assert tdoa[at : at + len(TDOA_FIELDS)] == list(TDOA_FIELDS)
    assert [k for k in tdoa if k not in TDOA_FIELDS] == list(twr)
    for name in ("landing", "landing-moving"):
        plain = mc_landing.columns(load_landing(name))
        assert not any(k.startswith("tdoa_") for k in plain), name
        with_tdoa = list(mc_landing.columns(load_landing(name, {"uwb.mode": "tdoa3"})))
        assert [k for k in with_tdoa if k not in mc_landing.TDOA_COLUMNS] == list(plain), name
        at = list(plain).index("uwb_range_m") + 1  # after the landing's own columns, before a moving pad's
        assert with_tdoa[at : at + len(mc_landing.TDOA_COLUMNS)] == list(mc_landing.TDOA_COLUMNS), name


def test_a_tdoa_docking_run_reports_each_chasers_differences():
    """10 s on TDoA3 with eight anchors: the chaser's filter gates every difference its tag forms, at the
    closed-form rate (within 5 %, as tests/test_docking_tdoa.py: the closed form is good to ~1 %, ~3,200 rows
    count to < 2 %), and rejects almost none; its rejections are the filter's range rejections."""
    sc = load_scenario("docking", DOCKING_TDOA)
    (row,), _ = run_one(sc, "fixed", 0, SEED)
    assert set(row) == set(fields_for(sc))
    rate = expected_rates(replace(sc.tdoa, mode="tdoa3"), len(CUBE)).measurements_per_tag_hz
    acc, rej = row["tdoa_accepted"], row["tdoa_rejected"]
    assert (acc + rej) / row["sim_time_s"] == pytest.approx(rate, rel=0.05)
    assert rej == row["rejected_ranges"] and rej < 0.01 * acc


def test_a_tdoa_landing_run_reports_the_uavs_differences_and_their_nis():
    """A TDoA3 landing: the UAV's filter gates at most the closed-form rate of its four anchors (fewer while
    one is out of reach) and more than a third of it (the anchors' reach is >= 8 m, the flight starts 13 m
    from the pad), rejects under 1 % (0.1-0.3 % on seeds 0-2, BENCHMARKS.md "Landing on TDoA"), and the mean
    NIS of the accepted differences is that of a consistent filter: in [0.7, 1.4], the bound
    tests/test_landing_tdoa.py puts on each anchor pair's (0.95-1.13 there)."""
    sc = load_landing("landing", LANDING_TDOA)
    (row,), _ = mc_landing.run_one(sc, "fixed", 0, SEED)
    assert set(row) == set(mc_landing.columns(sc))
    rate = expected_rates(replace(sc.tdoa, mode="tdoa3"), len(sc.uwb.anchors_m)).measurements_per_tag_hz
    acc, rej = row["tdoa_accepted"], row["tdoa_rejected"]
    per_s = (acc + rej) / row["sim_time_s"]
    assert rate / 3.0 < per_s <= 1.05 * rate, (per_s, rate)
    assert rej < 0.01 * acc
    assert 0.7 <= row["tdoa_nis_mean"] <= 1.4


def test_the_pooled_nis_weighs_each_pair_by_its_accepted_rows():
    pairs = {
        "0-1": {"accepted": 3, "rejected": 0, "refused": 0, "rejected_share": 0.0, "nis_mean": 2.0},
        "1-2": {"accepted": 1, "rejected": 1, "refused": 0, "rejected_share": 0.5, "nis_mean": 6.0},
        "2-3": {"accepted": 0, "rejected": 2, "refused": 0, "rejected_share": 1.0, "nis_mean": None},
    }
    assert mc_landing.tdoa_nis_mean(pairs) == pytest.approx((3 * 2.0 + 1 * 6.0) / 4)
    assert mc_landing.tdoa_nis_mean({"2-3": pairs["2-3"]}) is None
