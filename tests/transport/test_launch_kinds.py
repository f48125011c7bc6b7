"""``swarm launch S --seed N`` equals ``swarm sim S --seed N`` bit for bit for every input the one tick has
(docs/architecture.md): mode-triggered faults (``docking-faults``) and dispersions (the world and the agents
draw them from the seed themselves) in one launched run, and another vehicle kind (``ground-docking``, with
wheel slip). ``tests/transport/test_launch.py`` has the plain ``docking``. Before the step was one
piece of code, the processes ignored mode-triggered fault windows and built an undispersed world (issue 12:
launch 112.16 s / sim 112.26 s on ``docking-faults --seed 3``; 112.57 s / 111.65 s dispersed).

One launched run per case, lockstep, real processes over real Zenoh on loopback (``tests.transport.procs``).
"""

from __future__ import annotations

import json
import sys
import uuid
import warnings

import pytest

from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking
from tests.transport.procs import Procs, free_port, loopback

RUN_S = 240.0  # wall-time ceiling of one launched run (a docking ~25 s, a ground docking ~10 s here)

DISPERSED = ["dispersions.position_sigma_m=0.05", "dispersions.mass_sigma_frac=0.03",
             "dispersions.inertia_sigma_frac=0.03", "estimator.accel_psd_m2_s3=1e-8"]  # fmt: skip
CASES = {
    # case: (scenario, seed, policy, --set overrides, pairs (--agents), --vehicles-per-process)
    "docking-faults dispersed": ("docking-faults", 3, "mdp", DISPERSED, 1, 1),
    "ground-docking": ("ground-docking", 1, "fixed",
                       ["vehicles.chaser.position_m=[0.4, 0.3, 0.05]",
                        "vehicles.chaser.euler_deg=[0.0, 0.0, 90.0]",
                        "kinds.ground.dispersions.wheel_slip_sigma_frac=0.05"], 1, 1),
    # issue 13: four pairs sharing one UWB channel (TDMA, 8 tags: 29.8 ranges/s each instead of 50), their
    # agents in two agent hosts of four vehicles each (--vehicles-per-process 4), their controller clocks
    # staggered (vehicle m controls on ticks m, m + 10, ...), the first 30 s of the run (the whole docking
    # takes ~80 s of wall time with ten processes on two cores)
    "docking 4 pairs TDMA, agent hosts, staggered": (
        "docking", 2, "fixed",
        ["uwb.tdma=true", "sim.max_duration_s=30.0", "swarm.stagger_control=true"], 4, 4,
    ),
}  # fmt: skip
FIELDS = ("docked", "docking_time_s", "effort", "position_error_m", "attitude_error_rad", "r1_m", "r2_m",
          "keepout_violated", "closest_approach_m", "final_mode", "modes", "estimator")  # fmt: skip


def _sim(scenario: str, seed: int, policy: str, overrides: list[str], pairs: int) -> dict:
    from swarm.config import parse_override

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sc = load_scenario(scenario, dict(parse_override(o) for o in overrides))
    return run_docking(sc.with_pairs(pairs), policy, seed, record_series=False)


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_lockstep_launch_equals_the_in_process_run(case, tmp_path):
    scenario, seed, policy, overrides, pairs, per_process = CASES[case]
    want = _sim(scenario, seed, policy, overrides, pairs)
    ns = f"test-{uuid.uuid4().hex[:8]}"
    out = tmp_path / "launch.json"
    args = [sys.executable, "-m", "swarm.cli.main", "launch", scenario, "--headless", "--seed", str(seed),
            "--policy", policy, "--namespace", ns, "--listen", loopback(free_port()), "--until-docked",
            "--json", str(out), "--agents", str(pairs),
            "--vehicles-per-process", str(per_process)]  # fmt: skip
    for o in overrides:
        args += ["--set", o]
    with Procs() as procs:
        proc = procs.start(args)
        rc = proc.wait(RUN_S)
        text = proc.output()
    assert rc == (0 if all(c["docked"] for c in want["chasers"].values()) else 1), text  # 1: not all docked
    assert "Traceback" not in text
    got = json.loads(out.read_text())
    assert sorted(got["chasers"]) == sorted(want["chasers"]) and len(want["chasers"]) == pairs
    for cid, w in want["chasers"].items():
        c = got["chasers"][cid]
        for field in FIELDS:
            assert c[field] == w[field], (cid, field, c[field], w[field])
        if policy == "mdp":
            assert c["decisions"] == w["decisions"]
        if "faults" in case:  # the mode-triggered windows opened in the launched world too
            assert {e["fault"] for e in w["faults"]["events"]} == {"uwb_dropout", "camera_loss"}
        assert c["kind"] == w["kind"] == load_scenario(scenario).vehicles["chaser"].kind
    assert got["target_effort"] == want["target_effort"]
    hosts = sorted(name for name in got["restarts"] if name.startswith("agent"))
    assert len(hosts) == 2 * pairs // per_process, hosts  # the processes the agents ran in
