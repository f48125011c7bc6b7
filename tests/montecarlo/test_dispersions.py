"""Dispersions declared in the scenario (swarm.kinds.dispersions) and applied inside DockingSim."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarm.core import rotations as rot
from swarm.core.thrusters import allocation_matrix, nozzle_geometry
from swarm.errors import ConfigError
from swarm.kinds.cubesat import KP_B, KP_HMAX, KP_IXX, KP_IZZ, KP_MASS
from swarm.kinds.dispersions import DispersionParams, draw_dispersion
from swarm.scenario import Scenario, load_scenario
from swarm.sim.docking import DockingSim
from swarm.step.world import World, initial_truth

ALL_ON = {
    "dispersions.position_sigma_m": 0.05,
    "dispersions.velocity_sigma_m_s": 0.002,
    "dispersions.attitude_sigma_deg": 3.0,
    "dispersions.mass_sigma_frac": 0.05,
    "dispersions.inertia_sigma_frac": 0.05,
    "kinds.cubesat.dispersions.thruster_misalignment_deg": 1.0,
}


def test_dispersions_are_off_in_the_bundled_scenario_and_the_defaults():
    assert load_scenario("docking").dispersions == DispersionParams() == Scenario().dispersions
    assert not DispersionParams().enabled


def test_off_dispersions_leave_the_world_exactly_nominal():
    sc = load_scenario("docking")
    sim = DockingSim(sc, "fixed", 11, record_series=False)
    for i, vid in enumerate(sc.vehicles):
        x = np.zeros(13)
        x[0:3], x[6:10] = sc.vehicles[vid].position_m, sc.q0(vid)
        assert np.array_equal(sim.world.X[i], x)
        d = sc.kind(vid).p.dynamics
        kp = sim.world.KP[i]
        assert np.array_equal(kp[: KP_HMAX + 1], [d.mass_kg, *d.inertia_diag_kgm2, d.integration_step_s])
        B = allocation_matrix(sc.kind(vid).p.thrusters)
        assert np.array_equal(sim.world.truth_act[i].B, B)
        assert np.array_equal(kp[KP_B:].reshape(6, -1), B)  # the compiled hold's copy of the nozzles


def test_dispersions_change_the_truth_and_the_initial_estimate_follows_it():
    sc = load_scenario("docking", ALL_ON)
    nominal = World(load_scenario("docking"), 5)
    sim = DockingSim(sc, "mdp", 5, record_series=False)
    disp = draw_dispersion(sc, 5)
    c = list(sc.vehicles).index("chaser")
    dc, dt = disp.vehicles["chaser"], disp.vehicles["target"]
    np.testing.assert_array_equal(sim.world.X[c, 0:3], nominal.X[c, 0:3] + dc.position_m)
    np.testing.assert_array_equal(sim.world.X[c, 3:6], dc.velocity_m_s)
    att = rot.attitude_error(nominal.X[c, 6:10], sim.world.X[c, 6:10])
    np.testing.assert_allclose(att, dc.attitude_rad, atol=1e-12)
    t = list(sc.vehicles).index("target")
    assert np.array_equal(sim.world.X[t], nominal.X[t])  # the target's pose is not dispersed
    # each vehicle has its own mass and inertia draw (the target's no longer follows the chaser's)
    for i, d in ((c, dc), (t, dt)):
        assert sim.world.KP[i, KP_MASS] == nominal.KP[i, KP_MASS] * d.mass_factor
        np.testing.assert_array_equal(
            sim.world.KP[i, KP_IXX : KP_IZZ + 1], nominal.KP[i, KP_IXX : KP_IZZ + 1] * d.inertia_factor
        )
    assert dc.mass_factor != dt.mass_factor
    p = sc.kind("chaser").p
    r, d = nozzle_geometry(p.thrusters)
    for i, vd in ((c, dc), (t, dt)):
        d_true = Rotation.from_rotvec(vd.kind["thruster_rotvec_rad"]).apply(d)  # scipy as the oracle
        B = sim.world.truth_act[i].B
        np.testing.assert_allclose(B, np.vstack([d_true.T, np.cross(r, d_true).T]), atol=1e-15)
        assert not np.allclose(B, allocation_matrix(p.thrusters))
    # the agents keep the nominal models; the initial estimate is the dispersed truth plus the [initial] error
    err = sim.agents["chaser"].est.p_nav[0] - sim.world.X[c, 0:3]
    assert np.linalg.norm(err) < 5 * math.sqrt(3) * sc.initial.sigma_position_m
    assert sim.agents["chaser"].mass_kg == p.dynamics.mass_kg


def test_an_agent_process_starts_from_the_dispersed_truth_the_world_has():
    """``initial_truth`` (what an agent process builds its estimate from) is the world's row: the world
    process and the agents of one launched run agree on the dispersed start."""
    sc = load_scenario("docking", ALL_ON)
    w = World(sc, 7)
    for i, vid in enumerate(sc.vehicles):
        np.testing.assert_array_equal(initial_truth(sc, 7, vid), w.X[i])
    assert not np.array_equal(w.X[0], World(load_scenario("docking"), 7).X[0])


def test_each_quantity_has_its_own_stream():
    # switching the mass dispersion on does not change the position draws (and vice versa)
    a = draw_dispersion(load_scenario("docking", {"dispersions.position_sigma_m": 0.05}), 9)
    b = draw_dispersion(load_scenario("docking", {"dispersions.position_sigma_m": 0.05,
                                                  "dispersions.mass_sigma_frac": 0.05}), 9)  # fmt: skip
    np.testing.assert_array_equal(a.position_m["chaser"], b.position_m["chaser"])
    assert a.vehicles["chaser"].mass_factor == 1.0 and b.vehicles["chaser"].mass_factor != 1.0


def test_same_seed_same_draws_other_seed_other_draws():
    sc = load_scenario("docking", ALL_ON)
    a, b, c = draw_dispersion(sc, 1), draw_dispersion(sc, 1), draw_dispersion(sc, 2)
    for v in sc.vehicles:
        np.testing.assert_array_equal(
            a.vehicles[v].kind["thruster_rotvec_rad"], b.vehicles[v].kind["thruster_rotvec_rad"]
        )
    assert not np.array_equal(a.position_m["chaser"], c.position_m["chaser"])


@pytest.mark.parametrize("distribution", ["normal", "uniform"])
def test_draws_have_the_declared_standard_deviation(distribution):
    sc = load_scenario(
        "docking", {"dispersions.position_sigma_m": 0.04, "dispersions.distribution": distribution}
    )
    x = np.array([draw_dispersion(sc, s).position_m["chaser"] for s in range(3000)]).ravel()
    # 9000 draws: the sample std of a normal is within 3 % of sigma at ~4.5 standard errors (se ~ 0.75 %)
    assert abs(np.std(x) / 0.04 - 1.0) < 0.03
    assert abs(np.mean(x)) < 4 * 0.04 / math.sqrt(x.size)
    if distribution == "uniform":
        assert np.max(np.abs(x)) <= math.sqrt(3) * 0.04


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("position_sigma_m", -0.1),
        ("mass_sigma_frac", 0.5),
        ("distribution", '"cauchy"'),
        ("attitude_sigma_deg", "nan"),
    ],
)
def test_bad_dispersion_is_named(key, value):
    from swarm.config import parse_override

    k, v = parse_override(f"dispersions.{key}={value}")
    with pytest.raises(ConfigError, match=f"dispersions.{key}"):
        load_scenario("docking", {k: v})
