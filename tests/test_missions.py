"""The mission registry (swarm/missions, docs/architecture.md "Adding a mission"): which mission a scenario
file is, the refusals of a file that names none or an unknown one, and a toy mission registered from this
file and run through ``swarm sim`` and ``swarm montecarlo`` (the one campaign runner) without a line of any
runner changed."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

import swarm.missions as missions
from swarm.cli.main import main
from swarm.config import load_toml
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.missions import MISSIONS, Mission, mission_of, register, scenario_path
from swarm.montecarlo.campaign import run_seed
from swarm.scenario import load_scenario
from swarm.scenario_tables import MissionTable

SCENARIOS = Path(missions.__file__).resolve().parent.parent / "scenarios"


# ------------------------------------------------------------------------------ the toy mission (the recipe)


@dataclass(frozen=True)
class ToyScenario:
    """A point on a line that moves to a target at a constant speed."""

    mission: MissionTable = field(default_factory=lambda: MissionTable("toy"))
    """What the file says (``[mission] name = "toy"``)."""
    name: str = "toy"
    policy: str = "fixed"
    """``fixed``: ``speed_m_s``; ``mdp``: twice that (a toy's faster policy)."""
    start_m: float = 0.0
    """Nominal start [m]."""
    start_sigma_m: float = 1.0
    """Standard deviation of the start, drawn from the run's seed [m]."""
    target_m: float = 10.0
    speed_m_s: float = 1.0
    dt_s: float = 0.01
    max_duration_s: float = 30.0


class ToyMission(Mission):
    """Step 1 of the recipe: a Mission subclass with its name, success flag, metrics, load and run_one."""

    name = "toy"
    success_key = "reached"
    summary_metrics = ("time_s", "distance_m")

    def load(self, scenario, overrides=None):
        return load_toml(ToyScenario, scenario_path(scenario), overrides)

    def run_one(self, scenario, policy, seed):
        sc = scenario
        policy = policy or sc.policy
        rng = np.random.default_rng(seed)
        x = sc.start_m + sc.start_sigma_m * rng.standard_normal()
        distance_m = abs(sc.target_m - x)
        v = sc.speed_m_s * (2.0 if policy == "mdp" else 1.0)
        t = 0.0
        while abs(sc.target_m - x) > v * sc.dt_s / 2 and t < sc.max_duration_s:
            x += np.sign(sc.target_m - x) * v * sc.dt_s
            t += sc.dt_s
        reached = abs(sc.target_m - x) <= v * sc.dt_s / 2
        return {"policy": policy, "reached": bool(reached), "time_s": t, "distance_m": distance_m}


@pytest.fixture
def toy():
    """Step 2 of the recipe: register it (here for one test only)."""
    mission = register(ToyMission())
    yield mission
    del MISSIONS["toy"]


def _toy_file(tmp_path: Path, body: str = "") -> Path:
    """Step 3 of the recipe: a scenario file that says ``[mission] name = "toy"``."""
    path = tmp_path / "toy.toml"
    path.write_text('name = "toy-line"\n' + body + '[mission]\nname = "toy"\n')
    return path


# ------------------------------------------------------------------------------------------ the lookup


def test_the_bundled_scenarios_name_their_missions():
    assert {"docking", "landing"} <= set(MISSIONS)
    assert mission_of("docking").name == "docking"  # [mission] name = "docking"
    assert mission_of("ground-docking").name == "docking"
    assert mission_of("landing").name == "landing"  # [mission] name = "landing"
    assert mission_of(SCENARIOS / "landing-swarm.toml").name == "landing"


def test_an_unknown_mission_is_refused_naming_the_file_line_key_value_and_the_registered_names(tmp_path):
    path = tmp_path / "orbit.toml"
    path.write_text('name = "x"\n[mission]\nname = "orbit"\n')
    with pytest.raises(ConfigError) as err:
        mission_of(path)
    msg = str(err.value)
    assert str(path) in msg and "(line 3)" in msg and 'mission.name = "orbit"' in msg, msg
    assert "registered: docking, landing" in msg, msg


def test_a_mission_that_is_no_string_is_refused(tmp_path):
    path = tmp_path / "n.toml"
    path.write_text("[mission]\nname = 3\n")
    with pytest.raises(ConfigError, match=r"mission.name = 3 is not a registered mission"):
        mission_of(path)


@pytest.mark.parametrize("load", [mission_of, load_landing, load_scenario])
def test_the_old_top_level_mission_key_is_refused_with_the_table_to_write(tmp_path, load):
    text = (SCENARIOS / "landing.toml").read_text().replace('[mission]\nname = "landing"\n', "")
    path = tmp_path / "old.toml"
    path.write_text('# a file of the format before [mission]\nmission = "landing"\n' + text)
    with pytest.raises(ConfigError) as err:  # by the registry and by either loader called directly
        load(path)
    msg = str(err.value)
    assert msg.startswith(f"{path} (line 2): "), msg
    assert 'write [mission] name = "landing" instead' in msg, msg


def test_a_landing_file_without_its_mission_key_is_refused_with_the_key_to_write(tmp_path):
    text = (SCENARIOS / "landing.toml").read_text()
    path = tmp_path / "old-landing.toml"
    path.write_text(text.replace('[mission]\nname = "landing"\n', ""))
    with pytest.raises(ConfigError) as err:
        mission_of(path)
    msg = str(err.value)
    assert str(path) in msg and 'write [mission] name = "landing"' in msg, msg
    # the keys that gave it away, each with its line ([pad] is a landing table, docking has none)
    pad_line = next(n for n, line in enumerate(path.read_text().splitlines(), 1) if line.strip() == "[pad]")
    assert "more" in msg or f"pad (line {pad_line})" in msg, msg


def test_a_docking_file_without_the_table_or_with_it_is_docking(tmp_path):
    plain = tmp_path / "plain.toml"
    plain.write_text('name = "mine"\n[sim]\nmax_duration_s = 50.0\n')
    said = tmp_path / "said.toml"
    said.write_text('name = "mine"\n[mission]\nname = "docking"\n')
    assert mission_of(plain).name == mission_of(said).name == "docking"
    assert mission_of(plain).load(plain).sim.max_duration_s == 50.0
    assert mission_of(said).load(said).name == "mine"  # the key is read, not refused as unknown


def test_a_typo_in_a_docking_file_is_left_to_the_docking_loader(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text('name = "mine"\n[simm]\nmax_duration_s = 50.0\n')
    mission = mission_of(path)  # no other mission claims [simm]
    assert mission.name == "docking"
    with pytest.raises(ConfigError, match="simm"):
        mission.load(path)


def test_a_missing_file_is_left_to_the_default_loader_which_names_it(tmp_path):
    path = tmp_path / "absent.toml"
    with pytest.raises(ConfigError, match=r"absent\.toml"):
        mission_of(path).load(path)


def test_a_duplicate_or_nameless_mission_is_refused(toy):
    with pytest.raises(ConfigError, match="'toy' is registered already"):
        register(ToyMission())
    with pytest.raises(ConfigError, match="registered already"):
        register(type(MISSIONS["landing"])())
    with pytest.raises(ConfigError, match="a Mission with a name"):
        register(Mission())
    assert MISSIONS["toy"] is toy


def test_the_fault_menus_are_faults_the_swarm_knows():
    from swarm.transport.messages import FAULT_KINDS

    for mission in MISSIONS.values():
        assert mission.fault_menu and set(mission.fault_menu) <= set(FAULT_KINDS), mission


def test_the_summary_metrics_are_what_a_run_of_each_mission_reports():
    """A short run of each stack (a few simulated seconds: the goal is not reached, the fields exist)."""
    from swarm.sim.docking import run_docking
    from swarm.sim.landing import run_landing

    docking, landing = MISSIONS["docking"], MISSIONS["landing"]
    res = run_docking(docking.load("docking", {"sim.max_duration_s": 2.0}), seed=0, record_series=False)
    entry = res["chasers"]["chaser"]  # docking's summary fields are each chaser's
    assert {docking.success_key, *docking.summary_metrics} <= set(entry), sorted(entry)
    res = run_landing(landing.load("landing", {"max_duration_s": 2.0}), seed=0, record_series=False)
    assert {landing.success_key, *landing.summary_metrics} <= set(res), sorted(res)


# ------------------------------------------------------------------------------------- the toy, run


def test_a_toy_mission_flies_through_swarm_sim(toy, tmp_path, capsys):
    path = _toy_file(tmp_path, "target_m = 6.0\n")
    out = tmp_path / "toy.json"
    assert main(["sim", str(path), "--seed", "3", "--policy", "mdp", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    printed = capsys.readouterr().out
    assert "mission toy" in printed and "reached" in printed, printed
    # closed form: it covers the distance at 2 m/s, to within one step
    assert res["reached"] is True and res["policy"] == "mdp"
    assert res["time_s"] == pytest.approx(res["distance_m"] / 2.0, abs=0.02)
    x0 = np.random.default_rng(3).standard_normal()  # the seed reaches the toy's run_one
    assert res["distance_m"] == pytest.approx(6.0 - x0)


def test_a_toy_run_that_misses_exits_1_and_set_overrides_reach_it(toy, tmp_path):
    path = _toy_file(tmp_path)
    # 10 m at 1 m/s cannot be covered in 2 s
    assert main(["sim", str(path), "--set", "max_duration_s=2.0"]) == 1


def test_the_toy_refuses_what_it_does_not_have(toy, tmp_path, capsys):
    path = _toy_file(tmp_path)
    assert main(["sim", str(path), "--agents", "2"]) == 2
    assert "--agents: a toy scenario lists its vehicles" in capsys.readouterr().err
    assert main(["sim", str(path), "--plot", str(tmp_path / "p.png")]) == 2
    assert "--plot: mission 'toy'" in capsys.readouterr().err
    # no processes are launched for the toy: its Mission names no launch_entry
    assert main(["launch", str(path), "--headless"]) == 2
    assert "mission 'toy' has no processes to launch" in capsys.readouterr().err
    # nor a drawing: its Mission names no dashboard_drawer, so the dashboard refuses it
    assert main(["dashboard", str(path), "--port", "0"]) == 2
    assert "mission 'toy' has no dashboard drawer" in capsys.readouterr().err


def test_a_toy_campaign_pairs_its_policies_through_the_one_campaign_runner(toy, tmp_path, capsys):
    path = _toy_file(tmp_path)
    out, stats = tmp_path / "mc", tmp_path / "mc.json"
    argv = ["montecarlo", str(path), "--seed", "7", "--out", str(out), "--no-progress", "--json", str(stats)]
    assert main([*argv[:2], "--runs", "6", *argv[2:]]) == 0
    assert json.loads((out / "campaign.json").read_text())["mission"] == "toy"  # the runner's directory
    # resumed to 12 runs: the runner's resume, the 6 runs already there kept
    assert main(["montecarlo", str(out / "scenario.toml"), "--runs", "12", "--resume", str(out),
                 "--no-progress", "--json", str(stats)]) == 0  # fmt: skip
    rec = json.loads(stats.read_text())
    assert rec["paired_policies"] == ["fixed", "mdp"]
    assert rec["policies"]["fixed"]["reached"] == rec["policies"]["mdp"]["reached"] == 12
    rows = (out / "runs.csv").read_text().splitlines()
    assert rows[0] == "run,seed,policy,reached,time_s,distance_m" and len(rows) == 1 + 24
    # paired: run i of each policy starts at the same point (one seed per run index), so mdp - fixed of
    # the time is -d_i / 2 run by run; the oracle draws those starts itself (to within a step)
    d = np.array([10.0 - np.random.default_rng(run_seed(7, i)).standard_normal() for i in range(12)])
    paired = rec["paired"]["time_s"]
    assert paired["n"] == 12
    assert paired["mean_diff"] == pytest.approx(-np.mean(d) / 2, abs=0.02)
    assert paired["p_value"] is not None and paired["p_value"] < 1e-6  # 12 differences of ~ -5 s
    assert rec["policies"]["fixed"]["distance_m"]["mean"] == pytest.approx(np.mean(d))
    assert "mdp - fixed time_s" in capsys.readouterr().out
    assert json.loads((out / "stats.json").read_text()) == rec
