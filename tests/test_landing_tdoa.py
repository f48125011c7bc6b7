"""Landing on a TDoA radio (issue 45): ``uwb.mode = "tdoa3"`` / ``"tdoa2"`` in a landing scenario. The world
hands each UAV's tag the differences of the docking swarm's TDoA radio (:class:`swarm.core.tdoa_radio.
TdoaRadio`), the agent fuses them with log replay's robust update (:func:`swarm.step.landing_nb.agent_tdoa`),
and the wire carries them as ``Tdoa`` (launch == sim: tests/transport/test_landing_launch.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from swarm.core import tdoa_radio as tr
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.sim.landing import run_landing, run_landing_fleet
from swarm.step import landing_nb as lnb
from swarm.step.landing import LandingAgent, LandingInputs, LandingWorld
from swarm.transport import wire
from swarm.transport.keys import Keys
from swarm.transport.messages import Estimate, Tdoa, decode


def _fly(world, agents, k0, k1, record=None):
    """Ticks ``k0 .. k1 - 1`` of every UAV, as swarm sim's per-tick loop; ``record``: {id: [rows, ...]}."""
    for k in range(k0, k1):
        for uid, inp in world.step(k).items():
            if record is not None and inp.tdoa is not None:
                record.setdefault(uid, []).append(inp.tdoa.copy())
            world.hold(uid, agents[uid].tick(inp))


@pytest.mark.parametrize("mode", ["tdoa3", "tdoa2"])
def test_a_landing_on_a_tdoa_radio_lands_on_its_pad_fusing_the_differences(mode):
    """Seed 0 of landing.toml lands on either TDoA radio; the filter took the differences (hundreds: 4 anchors
    at 50 Hz on TDoA3 or one frame of 8 slots every 16.8 ms on TDoA2 give ~190-240 differences a second once
    in reach) and rejected few (gate at 0.9995 plus NLOS holds: a clean simulated radio has no NLOS; 2 %
    leaves room for the gate's tail on ~2500 rows and the descent's transients)."""
    sc = load_landing("landing", {"uwb.mode": mode})
    r = run_landing(sc, seed=0, record_series=False)
    assert r["landed"] and r["landing_error_m"] <= sc.pad_tolerance_m, r
    n = r["tdoa_accepted"] + r["tdoa_rejected"]
    assert r["tdoa_accepted"] > 1000 and r["tdoa_rejected"] <= 0.02 * n, r
    assert r["tdoa_refused"] == 0 and r["tdoa_skipped"] == 0
    # per pair: the counts add up, and the filter is consistent on each pair heard often: the mean NIS of
    # >= 100 accepted rows of a chi-square(1) has a sigma <= 0.14 were they independent (they correlate
    # through the slow errors): [0.7, 1.4] (measured 0.95-1.13 on seed 0)
    pairs = r["tdoa_pairs"]
    assert sum(v["accepted"] for v in pairs.values()) == r["tdoa_accepted"]
    often = [v["nis_mean"] for v in pairs.values() if v["accepted"] >= 100]
    assert often and all(0.7 <= x <= 1.4 for x in often), pairs


def test_twr_landings_carry_no_tdoa_counts_and_twr_is_the_default():
    sc = load_landing("landing")
    assert sc.uwb.mode == "twr"
    r = LandingAgent(sc, 0, 0, "mdp").outcome()
    assert not any(k.startswith("tdoa_") for k in r)


def test_each_uavs_rows_name_only_anchors_in_its_reach_and_do_not_depend_on_the_other_uavs():
    """The landing swarm on TDoA3: every row's two anchors are within the UAV's reach of its tag (rows of
    the others are taken out); a UAV's rows are the same in a fleet of 4 tags as alone in a fleet of 1, and
    whether the others fly or are done (each tag has its own draws, the channel is shared: tags never
    transmit, so they do not change the anchors' packets)."""
    sc = load_landing("landing-swarm", {"uwb.mode": "tdoa3", "dispersions.enabled": False})
    first = sc.uavs()[0].id
    runs = []
    for fleet_sc, fly in ((sc, None), (sc, first), (replace(sc, fleet=sc.fleet[:1]), None)):
        world = LandingWorld(fleet_sc, 3)
        for uid in world.uavs:
            world.uavs[uid].done = fly is not None and uid != fly
        agents = {u.id: LandingAgent(fleet_sc, 3, u.index, sc.policy) for u in fleet_sc.uavs()}
        got: dict = {}
        _fly(world, agents, 1, 301, got)
        runs.append(got[first])
    assert world.tdoa.n_tags == 1 and len(runs[0]) == 150  # every UWB tick (50 Hz), rows or none
    for other in runs[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(runs[0], other, strict=True))
    got = {first: runs[0]}
    # rows only of pairs of the anchors within 30 m of a start 20-25 m out (3 of 7 at first; 192 rows here)
    assert sum(len(r) for r in got[first]) > 100
    # the reach: with the default 15 m the far starts hear nothing at first
    far = LandingWorld(load_landing("landing", {"uwb.mode": "tdoa3"}), 0)
    inp = far.step(2)["uav"]
    u = far.uavs["uav"]
    reach = np.linalg.norm(far.anchors - u.x[0:3], axis=1) <= u.WC[lnb.WC_UWB_RANGE]
    assert not reach.all() and inp.tdoa is not None
    assert all(reach[int(a)] and reach[int(b)] for a, b, _ in inp.tdoa)


def test_a_difference_naming_an_unknown_anchor_is_skipped_and_counted_never_fused():
    """Rows naming anchor 99, the same anchor twice, a NaN anchor or a NaN difference are skipped and counted
    (``tdoa_skipped``, refused in the Estimate's counts); the filter is what the valid rows alone make it,
    to the bit."""
    sc = load_landing("landing", {"uwb.mode": "tdoa3", "uwb.max_range_m": 40.0, "dispersions.enabled": False})
    world = LandingWorld(sc, 0)
    a, b = LandingAgent(sc, 0, 0, "mdp"), LandingAgent(sc, 0, 0, "mdp")
    bad = np.array([[0.0, 99.0, 1.0], [1.0, 1.0, 0.0], [np.nan, 2.0, 0.5], [0.0, 2.0, np.nan]])
    n_bad = 0
    for k in range(1, 121):
        inp = world.step(k)["uav"]
        if inp.tdoa is not None and len(inp.tdoa):
            mixed = LandingInputs(**{**vars(inp), "tdoa": np.vstack([bad[:2], inp.tdoa, bad[2:]])})
            n_bad += len(bad)
            a.tick(mixed)
        else:
            a.tick(inp)
        cmd = b.tick(inp)
        world.hold("uav", cmd)
    assert n_bad > 0 and a.tdoa_counts()["tdoa_skipped"] == n_bad
    assert b.tdoa_counts()["tdoa_skipped"] == 0
    assert a.tdoa_counts()["tdoa_accepted"] == b.tdoa_counts()["tdoa_accepted"] > 0
    assert np.array_equal(a.filt.X, b.filt.X) and np.array_equal(a.filt.P, b.filt.P)
    out, _ = wire.landing_agent_tick(Keys("t"), "uav", a, a.tick(world.step(121)["uav"]), 0)
    est = decode(out[1][1], Estimate)
    assert est.counts["range_refused"] == n_bad


def test_the_world_publishes_a_tdoa_every_uwb_tick_and_the_agent_takes_it_back_to_the_bit():
    """``world_tick`` on a TDoA radio: a ``Tdoa`` on ``agent/<id>/tdoa`` every UWB tick (no rows when the tag
    heard none), no ``Uwb``; decoded it is the world's rows, bit for bit."""
    sc = load_landing("landing", {"uwb.mode": "tdoa3", "uwb.max_range_m": 40.0, "dispersions.enabled": False})
    world, keys = LandingWorld(sc, 0), Keys("w")
    seen = 0
    for k in range(1, 41):
        inputs = world.step(k)
        out = dict(wire.landing_world_tick(keys, world, k, inputs, 0))
        assert keys.uwb("uav") not in out
        assert (keys.tdoa("uav") in out) == world.rates.tdoa_tick(sc, k)
        if keys.tdoa("uav") in out:
            rows = wire.tdoa_input(decode(out[keys.tdoa("uav")], Tdoa))
            want = inputs["uav"].tdoa
            assert rows.shape == want.shape and np.array_equal(rows, want)
            seen += len(rows)
    assert seen > 0


def test_a_world_and_agent_restored_mid_flight_go_on_as_the_uninterrupted_ones():
    """The world's snapshot carries the TDoA radio's tag engines and draws (the channel is the seed's): a
    world and an agent restored at tick 150 into new ones give the same rows and the same filter after."""
    sc = load_landing("landing", {"uwb.mode": "tdoa3", "uwb.max_range_m": 40.0, "dispersions.enabled": False})
    world, agent = LandingWorld(sc, 1), LandingAgent(sc, 1, 0, "mdp")
    _fly(world, {"uav": agent}, 1, 151)
    w2, a2 = LandingWorld(sc, 1), LandingAgent(sc, 1, 0, "mdp")
    w2.restore(world.snapshot())
    a2.restore(agent.snapshot())
    r1: dict = {}
    r2: dict = {}
    _fly(world, {"uav": agent}, 151, 201, r1)
    _fly(w2, {"uav": a2}, 151, 201, r2)
    assert sum(len(r) for r in r1["uav"]) > 0
    assert all(np.array_equal(x, y) for x, y in zip(r1["uav"], r2["uav"], strict=True))
    assert np.array_equal(agent.filt.X, a2.filt.X)
    twr = LandingWorld(load_landing("landing"), 1)
    with pytest.raises(ValueError, match="radio"):
        twr.restore(world.snapshot())


def test_the_compiled_path_is_not_taken_on_a_tdoa_radio():
    """``compiled=True`` flies a TDoA landing tick by tick (the compiled loop carries no differences: it would
    fuse none): the same summary as ``compiled=False``, by construction (nothing more is claimed)."""
    over = {"uwb.mode": "tdoa3", "max_duration_s": 3.0, "uwb.max_range_m": 40.0, "dispersions.enabled": False}
    sc = load_landing("landing", over)
    a = run_landing_fleet(sc, seed=2, record_series=False, compiled=True)
    b = run_landing_fleet(sc, seed=2, record_series=False, compiled=False)
    for uid in a["uavs"]:
        x, y = a["uavs"][uid], b["uavs"][uid]
        assert {k: v for k, v in x.items() if k not in ("wall_s", "realtime_factor")} == {
            k: v for k, v in y.items() if k not in ("wall_s", "realtime_factor")
        }
        assert x["tdoa_accepted"] > 0


def test_a_tdoa_landing_needs_two_anchors_and_a_known_mode():
    with pytest.raises(ConfigError, match=r"uwb\.mode must be 'twr', 'tdoa2' or 'tdoa3'"):
        load_landing("landing", {"uwb.mode": "tdoa"})
    with pytest.raises(ConfigError, match="needs at least 2 anchors, got 1"):
        load_landing("landing", {"uwb.mode": "tdoa3", "uwb.anchors_m": [[0.0, 0.0, 1.0]]})
    assert tr.TdoaParams().mode == "tdoa3"


def test_the_range_errors_reach_the_differences_per_anchor_and_a_dropout_empties_them():
    """The TWR model's per-anchor offsets (one draw for the fleet) and each UAV's take-off steps are the TDoA
    radio's link errors (so they enter as differences, :mod:`swarm.core.tdoa_radio`); a ``uwb_dropout``
    window leaves a UAV's Tdoa without rows (still sent: the agent does not wait)."""
    over = {"uwb.mode": "tdoa3", "uwb.offset_spread_m": 0.1, "uwb.takeoff_bias_step_m": 0.05,
            "uwb.max_range_m": 40.0, "dispersions.enabled": False}  # fmt: skip
    sc = load_landing("landing-swarm", over)
    world = LandingWorld(sc, 0)
    u = list(world.uavs.values())
    errs = world.tdoa.errors
    assert np.any(errs.offset_m != 0.0) and np.array_equal(errs.offset_m, u[0].ERR_OFF)
    assert np.array_equal(errs.step_m, np.array([v.ERR_STEP for v in u]))
    world.add_fault("uwb_dropout", 0.5, 0.3, [u_.id for u_ in sc.uavs()[:1]])
    first, second = sc.uavs()[0].id, sc.uavs()[1].id
    rows = {first: [], second: []}
    for k in range(1, 100):  # (no agents: the rotors hold the hover speed the world starts with)
        for uid, inp in world.step(k).items():
            if inp.tdoa is not None and uid in rows and 0.5 <= k * sc.dt_s < 0.8:
                rows[uid].append(len(inp.tdoa))
    assert len(rows[first]) == 15 and sum(rows[first]) == 0  # every UWB tick of the window, no rows
    assert sum(rows[second]) > 0


def test_a_tdoa_message_naming_an_unknown_anchor_decodes_and_its_row_is_skipped_by_the_agent():
    """On the wire a ``Tdoa`` names anchors by id (any 0 to 2**31 - 1: the message does not know the
    scenario); the landing agent skips and counts the row naming anchor 7 of a 4-anchor scenario and fuses
    the other."""
    from swarm.transport.messages import encode_tdoa

    sc = load_landing("landing", {"uwb.mode": "tdoa3", "uwb.max_range_m": 40.0, "dispersions.enabled": False})
    world, agent = LandingWorld(sc, 0), LandingAgent(sc, 0, 0, "mdp")
    for k in range(1, 60):
        world.hold("uav", agent.tick(world.step(k)["uav"]))
    inp = world.step(60)["uav"]
    msg = decode(encode_tdoa(60, 0.6, np.array([[0.0, 7.0, 1.5], [0.0, 1.0, 0.2]])), Tdoa)
    inp.tdoa = wire.tdoa_input(msg)
    before = agent.tdoa_counts()
    agent.tick(inp)
    after = agent.tdoa_counts()
    assert after["tdoa_skipped"] == before["tdoa_skipped"] + 1
    n = sum(after[k] - before[k] for k in ("tdoa_accepted", "tdoa_rejected", "tdoa_refused"))
    assert n == 1 and np.all(np.isfinite(agent.filt.X))
