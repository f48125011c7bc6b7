"""What the launcher keeps of a run's guidance (``swarm.cli.launch.RunLog``): bounded however long the run,
and the summary it gives the one of the whole stream (the last guidance before the contact, every Algorithm
1 record up to it, once each)."""

from __future__ import annotations

from swarm.cli.launch import GUIDANCE_KEPT, RunLog
from swarm.cli.launch_missions import summarize
from swarm.core.decision_keys import DECISION_KEYS
from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Event, Guidance

MODES = ("APPROACH", "REORIENT", "ALIGN", "DOCK")


def _decision(t_s: float) -> dict:
    return {k: (t_s if k == "t_s" else 0.5) for k in DECISION_KEYS}


def _stream(n: int, contact_at: int) -> list[Guidance]:
    """``n`` guidance messages at 10 Hz, an Algorithm 1 record every 7th (each carried until the next),
    the mode and radii changing along, and going on past the contact (message ``contact_at``)."""
    out, dec = [], None
    for i in range(n):
        t = 0.1 * i
        if i % 7 == 3:
            dec = _decision(t)
        out.append(Guidance(i * 10, t, MODES[(i // 50) % 4], 1.0, 0.3 + 1e-4 * i, 0.7 + 1e-4 * i, 0.9, dec))
    return out


def _reference(stream: list[Guidance], t_end: float) -> tuple[Guidance, list[dict]]:
    """What the launcher made of every message it had kept (before it kept fewer)."""
    guid = [g for g in stream if g.t_s <= t_end]
    decisions, seen = [], set()
    for g in guid:
        if g.decision is not None and g.decision["t_s"] not in seen:
            seen.add(g.decision["t_s"])
            decisions.append(g.decision)
    return guid[-1], decisions


def test_a_long_run_keeps_a_bounded_guidance_log_and_summarizes_as_the_whole_stream():
    sc = load_scenario("docking")
    keys = Keys("t")
    cid = sc.chasers[0]
    n, contact_at = 6000, 4000  # 600 s at 10 Hz, contact at 400 s: far more than GUIDANCE_KEPT either side
    stream = _stream(n, contact_at)
    t_end = stream[contact_at].t_s
    contact = {"t_s": t_end, "docked": True, "docking_time_s": t_end, "position_error_m": 0.01,
               "attitude_error_rad": 0.02, "contact": {}, "to": "CONTACT", "range_m": 0.0,
               "reason": "contact"}  # fmt: skip
    log = RunLog()
    log.on_event(keys.event(cid), Event(0.0, "mode", {"to": "APPROACH", "t_s": 0.0, "range_m": 2.0,
                                                      "reason": "start"}), keys)  # fmt: skip
    for i, g in enumerate(stream):
        if i == contact_at + 5:  # the contact event comes a few guidance messages after its time
            log.on_event(keys.event(cid), Event(t_end, "contact", contact), keys)
        log.on_guidance(keys.guidance(cid), g, keys)
        assert len(log.guidance[cid]) <= GUIDANCE_KEPT
    got = summarize(sc, "mdp", 0, log, 1.0)["chasers"][cid]
    last, decisions = _reference(stream, t_end)
    assert (got["final_mode"], got["r1_m"], got["r2_m"]) == (last.mode, last.r1_m, last.r2_m)
    assert got["decisions"] == decisions and len(decisions) == len({d["t_s"] for d in decisions}) > 500
    # the guidance past the contact was not kept once the contact was known (a docked chaser flies on)
    assert all(g.t_s <= stream[contact_at + 4].t_s for g in log.guidance[cid])
    assert got["docked"] is True and got["modes"][-1]["t_s"] == t_end
