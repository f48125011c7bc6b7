"""What ``swarm launch`` does differently per mission (:mod:`swarm.cli.launch` runs the rest).

A mission's launch is a small plan, keyed by the mission's name (:data:`LAUNCHES`): how its scenario is
loaded and what is refused before anything starts, its vehicles, the processes of one run (the world, a
mothership or not, the agents and their flags), which of them the run cannot go on without, and how the
run's summary is made from what the launcher heard and judged. The router, the supervision, the
restarts, the dashboard, the summary's restarts and ``--json`` are the launcher's, once for all.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from swarm.cli.children import config_args
from swarm.cli.supervisor import Child

_LOG = logging.getLogger("swarm.launch")

VISION_COUNTS = ("features_accepted", "pose_accepted")
"""A docking agent's counters of accepted camera samples (its estimator's ``accepted_vision``)."""


def clock_name(clock, pace=None) -> str:
    """How a run's clock is told: ``lockstep``, ``lockstep paced at scaled:10``, ``free-running at
    realtime``."""
    if not clock.lockstep:
        return f"free-running at {clock}"
    return "lockstep" if pace is None else f"lockstep paced at {pace}"


def _hosted(args: argparse.Namespace) -> bool:
    """Whether the agents run in hosts of several vehicles, which take the world's and the mothership's
    batches (docs/protocol.md, "Rates")."""
    return getattr(args, "vehicles_per_process", 1) > 1


def world_args(args: argparse.Namespace) -> list[str]:
    """The docking world process's own flags (the common ones and its Zenoh config aside)."""
    world = ["swarm.world", "--clock", str(args.clock), "--step-timeout", str(args.step_timeout),
             "--start-timeout", str(args.start_timeout),
             "--checkpoint-dir", str(args.checkpoint_dir)]  # fmt: skip
    if args.pace is not None:
        world += ["--pace", str(args.pace)]
    if _hosted(args):  # one message for many vehicles' imu, one for their truths
        world += ["--batch"]
    if not args.bundles:
        world += ["--no-bundles"]
    return world


def mothership_args(args: argparse.Namespace) -> list[str]:
    """The mothership process's own flags (the common ones and its Zenoh config aside)."""
    return ["mothership", *(["--batch"] if _hosted(args) else [])]  # one message for many vehicles' ranges


class Docking:
    """A docking swarm: the world, the mothership and the agents (:mod:`agents.host`), laid out by
    :mod:`swarm.cli.launch_plan`; any of them restarted when lost (``--rejoin``; the world ``--resume``).
    After the run the swarm stays up (for the dashboard, or an outside client) unless ``--until-docked``."""

    name = "docking"
    mothership = True
    hold_headless = True
    agent_back = "rejoining the run"
    """How the launcher tells a restarted agent or mothership."""

    def load(self, args: argparse.Namespace):
        """The scenario (``--agents`` copies), with the launch plan's overrides (:func:`plan`)."""
        from swarm.transport.process import scenario_from

        sc = scenario_from(args)
        return scenario_from(args) if plan(args, sc) is not None else sc

    def vehicles(self, sc) -> list[str]:
        return list(sc.vehicles)

    def platforms(self, sc) -> tuple[str, ...]:
        return ()

    def guided(self, sc) -> list[str]:
        """The vehicles whose guidance the summary reads (the chasers')."""
        return list(sc.chasers)

    def essential(self, name: str) -> bool:
        """Whether the run cannot go on without this child for good (the world; a lost agent's vehicle
        coasts, its nozzles closed)."""
        return name == "world"

    def children(
        self, args, sc, hosts: dict[str, list[str]], common: list[str], run_dir: Path
    ) -> list[Child]:
        from swarm.transport.security import agent_name

        args.checkpoint_dir = run_dir
        out = [Child("mothership", [*mothership_args(args), *common, *config_args(args, "mothership")],
                     restartable=True, rejoin_args=["--rejoin"])]  # fmt: skip
        for name, vids in hosts.items():
            agent = ["agents", "--id", ",".join(vids), "--clock", str(args.clock), *common,
                     *config_args(args, agent_name(vids[0]))]  # fmt: skip
            out.append(Child(name, agent, restartable=True, rejoin_args=["--rejoin"]))
        world = [*world_args(args), *common, *config_args(args, "world")]
        return [*out, Child("world", world, restartable=True, rejoin_args=["--resume"])]

    def summary(self, args, sc, policy: str, seed: int, log, wall_s: float) -> dict:
        """:func:`summarize`, printed as ``swarm sim`` prints it."""
        from swarm.cli.sim import print_summary

        result = summarize(sc, policy, seed, log, wall_s)
        result["launch_plan"] = args.launch_plan
        print_summary(result)
        return result

    def ok(self, result: dict) -> bool:
        """Every chaser docked."""
        return bool(result["chasers"]) and all(c["docked"] for c in result["chasers"].values())


def plan(args: argparse.Namespace, sc):
    """The swarm's layout (:func:`swarm.cli.launch_plan.resolve_plan`): ``args.vehicles_per_process`` set,
    the ``--set`` overrides of the parts the plan chose added to ``args.overrides`` (the children load the
    scenario with them), the plan logged and kept for the summary (``args.launch_plan``). Returns the plan
    when it added overrides (the launcher's scenario must be loaded again), else None."""
    from swarm.cli.launch_plan import resolve_plan

    plan, extra = resolve_plan(len(sc.vehicles), args.clock.lockstep, args.vehicles_per_process,
                               args.overrides, secure=bool(getattr(args, "secure", False)))  # fmt: skip
    args.vehicles_per_process = plan.vehicles_per_process
    args.overrides = [*args.overrides, *extra]
    args.launch_plan = plan.as_dict()
    _LOG.info("launch plan: %s", plan.describe())
    return plan if extra else None


def summarize(sc, policy: str, seed: int, log, wall_s: float) -> dict:
    """The docking run summary with ``swarm sim``'s fields per chaser, from what the launcher heard
    (:class:`swarm.cli.launch.RunLog`)."""
    from swarm.step.outcome import chaser_summary, run_summary

    end = log.run_end or {}
    chasers = {}
    with log.lock:
        for cid in sc.chasers:
            events = log.events.get(cid, [])
            contact = next((e for e in events if e.kind in ("contact", "collision")), None)
            t_end = contact.data["t_s"] if contact is not None else float("inf")
            picked = [e.data for e in events if e.kind == "mode" and e.data.get("t_s", 0.0) <= t_end]
            picked.sort(key=lambda d: d["t_s"])
            if contact is not None:
                picked.append(contact.data)
            modes = [
                {"mode": d["to"], "t_s": d["t_s"], "range_m": d["range_m"], "reason": d["reason"]}
                for d in picked
            ]
            guid = [g for g in log.guidance.get(cid, ()) if g.t_s <= t_end]
            last = guid[-1] if guid else None
            decisions = [dec for t_s, dec in log.decisions.get(cid, {}).values() if t_s <= t_end]
            summary = log.summaries.get(cid, {})
            counts = summary.get("counts", {})
            c = chaser_summary(
                sc, cid,
                docked=bool(contact is not None and contact.data["docked"]),
                collided=bool(contact is not None and not contact.data["docked"]),
                docking_time_s=None if contact is None else contact.data["docking_time_s"],
                effort=end.get("effort", {}).get(cid),
                position_error_m=None if contact is None else contact.data["position_error_m"],
                attitude_error_rad=None if contact is None else contact.data["attitude_error_rad"],
                final_mode=last.mode if last is not None else summary.get("final_mode"),
                modes=modes,
                r1_m=last.r1_m if last is not None else summary.get("r1_m"),
                r2_m=last.r2_m if last is not None else summary.get("r2_m"),
                keepout_violated=any(e.kind == "keepout_violation" for e in events),
                closest_approach_m=end.get("closest_approach_m", {}).get(cid),
                contact=None if contact is None else contact.data["contact"],
                estimator={  # absent counters are zero; no summary at all: unknown
                    "rejected_ranges": counts.get("range_rejected", 0) if summary else None,
                    "accepted_ranges": counts.get("range_accepted", 0) if summary else None,
                    "accepted_vision": sum(counts.get(k, 0) for k in VISION_COUNTS) if summary else None,
                },
                wall_s=end.get("wall_s"),
                realtime_factor=end.get("realtime_factor"),
                restarted=any(e.kind == "restarted" for e in events),
                tick_assembly=summary.get("assembler"),  # the agent's drop counters of late/odd messages
            )  # fmt: skip
            if policy == "mdp":
                c["decisions"] = decisions
            chasers[cid] = c
    cpu = {"world": end.get("cpu_s"), **{v: s.get("cpu_s") for v, s in log.summaries.items()}}
    out = run_summary(sc, policy, seed, end.get("t_s"), end.get("wall_s", wall_s), end.get("effort", {}),
                      chasers, end_reason=end.get("reason", "no run_end received"), cpu_s=cpu)  # fmt: skip
    if end.get("realtime_factor") is not None:
        out["realtime_factor"] = end["realtime_factor"]
    for key in ("late_commands", "late_control_commands"):  # free-running: [late, of] (world/process.py)
        if end.get(key) is not None:
            out[key] = end[key]
    return out


class Landing:
    """A landing swarm: the landing world (:mod:`swarm.world.landing`) and the landing agents
    (:mod:`agents.landing`), a process per UAV unless ``--vehicles-per-process`` says, no mothership. The
    world and (lockstep) the agents are restarted warm from the checkpoints they write into the run's
    directory (``--resume``); free-running, a lost agent ends the run (the world would fly its UAV
    without a controller), so the agents are not restarted there. ``--max-restarts 0`` restarts nothing
    and writes no checkpoint. Headless, the launch exits when the run ends."""

    name = "landing"
    mothership = False
    hold_headless = False
    agent_back = "warm, from its checkpoint"

    def load(self, args: argparse.Namespace):
        """The scenario; ``--agents`` other than 1 refused (the file lists its UAVs)."""
        from swarm.missions import MISSIONS, overrides_of

        mission = MISSIONS[self.name]
        if args.vehicles_per_process is None:  # (a landing swarm has no automatic plan)
            args.vehicles_per_process = 1
        return mission.with_agents(mission.load(args.scenario, overrides_of(args)), args.agents)

    def vehicles(self, sc) -> list[str]:
        return [u.id for u in sc.uavs()]

    def platforms(self, sc) -> tuple[str, ...]:
        """The moving pad's robot, whose shared estimate the world puts (the access control's rights)."""
        return (sc.platform.id,) if sc.platform.enabled and sc.platform.share_estimate else ()

    def guided(self, sc) -> list[str]:
        return []

    def essential(self, name: str) -> bool:
        """Every process but the dashboard: nobody else flies a lost agent's UAV."""
        return name != "dashboard"

    def children(
        self, args, sc, hosts: dict[str, list[str]], common: list[str], run_dir: Path
    ) -> list[Child]:
        from swarm.transport.security import agent_name

        restarts = args.max_restarts > 0  # (--max-restarts 0: no restart, so no checkpoint written either)
        ckpt = ["--checkpoint-dir", str(run_dir)]
        agents_too = restarts and args.clock.lockstep  # (free-running, a lost agent ends the run)
        out = []
        for name, vids in hosts.items():
            agent = ["agents.landing", "--id", ",".join(vids), *common,
                     *config_args(args, agent_name(vids[0])), *(ckpt if agents_too else [])]  # fmt: skip
            out.append(Child(name, agent, restartable=agents_too, rejoin_args=["--resume"]))
        world = ["swarm.world.landing", "--clock", str(args.clock),
                 *(["--pace", str(args.pace)] if args.pace is not None else []),
                 "--step-timeout", str(args.step_timeout), "--start-timeout", str(args.start_timeout),
                 *common, *(ckpt if restarts else []), *config_args(args, "world")]  # fmt: skip
        return [*out, Child("world", world, restartable=restarts, rejoin_args=["--resume"])]

    def summary(self, args, sc, policy: str, seed: int, log, wall_s: float) -> dict | None:
        """``swarm sim``'s fields per UAV from the world's ``run_end`` and each agent's ``summary`` event
        (``decisions`` is the number of Algorithm 1 records: the records stay in the agent), printed;
        None if a UAV's summary is missing."""
        from swarm.cli.sim import print_landing
        from swarm.step.landing import landing_summary

        end, ids = log.run_end, self.vehicles(sc)
        missing = sorted(set(ids) - set(log.summaries))
        if missing:
            _LOG.error("no summary from %s", ", ".join(missing))
            return None
        wall = float(end.get("wall_s", wall_s))
        uavs = {}
        for uid in ids:
            w = end["uavs"][uid]
            uavs[uid] = landing_summary(sc, policy, seed, w, log.summaries[uid], w["end_tick"], wall)
            if "late_ticks" in w:  # free-running: ticks flown on an older command
                uavs[uid]["late_ticks"] = int(w["late_ticks"])
        result = {
            "scenario": sc.name, "policy": policy, "seed": seed, "camera_mode": sc.camera.mode,
            "landed": sum(1 for v in uavs.values() if v["landed"]), "uavs": uavs,
            "sim_time_s": round(int(end["ticks"]) * sc.dt_s, 4), "wall_s": wall,
            "run_end_reason": end.get("reason"),
        }  # fmt: skip
        for uid, r in uavs.items():
            print(f"[{uid}]", end=" ")
            print_landing(r)
        n_ok, sim_s, how = result["landed"], result["sim_time_s"], clock_name(args.clock, args.pace)
        print(f"{n_ok} of {len(ids)} UAVs landed on their pads in {sim_s:.1f} s simulated "
              f"({wall:.1f} s of wall time, {how} over Zenoh)", flush=True)  # fmt: skip
        late = {u: r["late_ticks"] for u, r in uavs.items() if "late_ticks" in r}
        if late:
            ticks = max(1, int(end["ticks"]))
            print("late ticks (flown on an older command): " + ", ".join(
                f"{u} {n} ({n / ticks:.1%})" for u, n in late.items()), flush=True)  # fmt: skip
        return result

    def ok(self, result: dict) -> bool:
        """The run done and every UAV landed on its pad or aborted safely."""
        uavs = result["uavs"].values()
        return result["run_end_reason"] == "done" and all(r["landed"] or r["aborted"] for r in uavs)


LAUNCHES = {m.name: m for m in (Docking(), Landing())}
"""Each mission's launch by the mission's name (:data:`swarm.missions.MISSIONS`)."""
