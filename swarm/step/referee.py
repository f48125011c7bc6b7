"""The referee: what the truth says about each chaser and its target at one tick (keep-out, contact).

:func:`referee_tick` is the arithmetic, compiled: the closest approach, the keep-out sphere and whether a
pair touches, for every pair at once. The in-process runner's fast path calls it tick by tick
(:mod:`swarm.step.tick`); :class:`Referee` calls it for one tick and adds what only a contact needs (its
geometry, docked or collided), for the in-process runner's Python ticks and for the world process. One
piece of code judges a run in every runner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from swarm.core import rotations as rot
from swarm.core.guidance import CORRIDOR_MODES, docking_geometry, pair_geometry

NO_CONTACT = -1


@dataclass(frozen=True)
class Contact:
    """The chaser's port touched the target (or the bodies met): the run of this chaser is over."""

    docked: bool
    """Within the contact tolerances (``guidance.contact_*``): docked; otherwise a collision."""
    t_s: float
    contact: dict
    """Port-to-port geometry on the truth (gap, lateral offset, attitude error, closing speed)."""
    position_error_m: float
    """Distance of the chaser's centre from its docked position on the target [m]."""
    attitude_error_rad: float
    """Angle between the chaser's attitude and its docked attitude [rad]."""
    range_m: float
    """Centre-to-centre distance [m]."""

    def event(self, from_mode: str) -> dict:
        """The mode-log entry of this contact (``"to"``: ``CONTACT`` or ``COLLISION``)."""
        reason = (
            "port contact within tolerance" if self.docked else f"contact outside tolerance {self.contact}"
        )
        to = "CONTACT" if self.docked else "COLLISION"
        return {"t_s": self.t_s, "from": from_mode, "to": to, "range_m": self.range_m, "reason": reason}


@njit(cache=True)
def keepout_from_geometry(centre, axial, keepout_r, corridor_cos, docking):
    """Keep-out violation from :func:`swarm.core.guidance.pair_geometry`'s centre distance and axial
    offset: inside the sphere and not (docking inside the corridor)."""
    if centre >= keepout_r:
        return False
    return not (docking and axial >= centre * corridor_cos)


@njit(cache=True)
def referee_tick(X, pairs, done, docking, n_target, q_tc, half, keepout_r, corridor_cos, contact_d, ko_flag,
                 ko_t, ko_r, closest, t_s):  # fmt: skip
    """Judge every pair ``(chaser, target)`` of ``pairs`` (P, 2) (vehicle rows of the truth ``X``) not
    ``done`` at ``t_s``: the closest centre distance outside the corridor modes (``docking`` False), the
    first keep-out violation (``ko_flag``/``ko_t``/``ko_r``), and contact. Returns the first pair that
    touches (its port reaches the target's docking face, or the centres come closer than a body side), or
    ``NO_CONTACT``. ``q_tc`` (P, 4): each chaser kind's docked attitude relative to its target."""
    for c in range(pairs.shape[0]):
        if done[c]:
            continue
        xc = X[pairs[c, 0]]
        xt = X[pairs[c, 1]]
        centre, gap, lateral, _att, _closing, axial = pair_geometry(
            xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[3:6], xt[6:10], n_target, q_tc[c], half
        )
        if not docking[c] and centre < closest[c]:
            closest[c] = centre
        if centre > keepout_r + 2.0 * half:
            continue
        if keepout_from_geometry(centre, axial, keepout_r, corridor_cos, docking[c]) and not ko_flag[c]:
            ko_flag[c] = True
            ko_t[c] = t_s
            ko_r[c] = centre
        touching = -2.0 * half <= gap <= contact_d and lateral <= 2.0 * half
        if touching or centre < 2.0 * half:
            return c
    return NO_CONTACT


class Referee:
    """The referee's state over a run (module docstring): per chaser, whether it is done, its closest
    approach and its first keep-out violation."""

    def __init__(self, scenario) -> None:
        sc = scenario
        self.sc = sc
        self.g = sc.guidance
        ids = list(sc.vehicles)
        self.chasers = list(sc.chasers)
        self.pairs = np.array([[ids.index(c), ids.index(sc.vehicles[c].target)] for c in self.chasers],
                              dtype=np.int64).reshape(-1, 2)  # fmt: skip
        self.q_tc = np.array([sc.guidance_for(c).q_target_chaser_docked for c in self.chasers]).reshape(-1, 4)
        n = len(self.chasers)
        self.done = np.zeros(n, dtype=np.bool_)
        self.docking = np.zeros(n, dtype=np.bool_)
        self.ko_flag = np.zeros(n, dtype=np.bool_)
        self.ko_t = np.zeros(n)
        self.ko_r = np.zeros(n)
        self.closest = np.full(n, np.inf)

    def set_modes(self, modes) -> None:
        """Each chaser's guidance mode (a map id -> mode name): the corridor modes may enter the sphere."""
        for c, cid in enumerate(self.chasers):
            self.docking[c] = str(modes[cid]) in CORRIDOR_MODES

    def tick(self, X, t_s: float) -> int:
        """:func:`referee_tick` on this state: the first pair that touches, or ``NO_CONTACT``."""
        g = self.g
        return referee_tick(
            X, self.pairs, self.done, self.docking, g.face_normal_target, self.q_tc, g.half_size_m,
            g.keepout_radius_m, g.corridor_cos, g.contact_distance_m, self.ko_flag, self.ko_t, self.ko_r,
            self.closest, t_s,
        )  # fmt: skip

    def judge(self, X, t_s: float, modes) -> tuple[list[tuple[str, float]], list[tuple[str, Contact]]]:
        """One tick: every chaser not done is judged on the truth ``X`` with its ``modes``. Returns the new
        keep-out violations ``[(chaser, centre distance)]`` and the contacts ``[(chaser, Contact)]`` (a
        contacted chaser is done from now on)."""
        self.set_modes(modes)
        before = self.ko_flag.copy()
        contacts = []
        while True:
            c = self.tick(X, t_s)
            if c == NO_CONTACT:
                break
            cid = self.chasers[c]
            contacts.append((cid, self.contact(X, c, t_s)))
            self.done[c] = True
        new_ko = [
            (cid, float(self.ko_r[c]))
            for c, cid in enumerate(self.chasers)
            if self.ko_flag[c] and not before[c]
        ]
        return new_ko, contacts

    def contact(self, X, c: int, t_s: float) -> Contact:
        """The details of pair ``c``'s contact at ``t_s``: docked within the tolerances, or collided."""
        g = self.g
        xc, xt = X[self.pairs[c, 0]], X[self.pairs[c, 1]]
        geo = pair_geometry(
            xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[3:6], xt[6:10], g.face_normal_target, self.q_tc[c],
            g.half_size_m,
        )  # fmt: skip
        geom = {"gap_m": geo[1], "lateral_m": geo[2], "attitude_rad": geo[3], "closing_m_s": geo[4]}
        ok = (
            geom["lateral_m"] <= g.contact_lateral_m
            and geom["attitude_rad"] <= g.contact_attitude_rad
            and geom["closing_m_s"] <= g.contact_speed_m_s
        )
        gc = self.sc.guidance_for(self.chasers[c])
        _, p_docked, q_dock = docking_geometry(gc, xt[0:3], xt[6:10])
        return Contact(
            docked=bool(ok), t_s=t_s, contact=geom,
            position_error_m=float(np.linalg.norm(xc[0:3] - p_docked)),
            attitude_error_rad=float(np.linalg.norm(rot.attitude_error(q_dock, xc[6:10]))),
            range_m=float(np.linalg.norm(xc[0:3] - xt[0:3])),
        )  # fmt: skip

    def closest_approach(self, chaser: str) -> float | None:
        """The chaser's closest true centre distance outside the corridor modes [m] (None before any)."""
        d = float(self.closest[self.chasers.index(chaser)])
        return d if math.isfinite(d) else None

    # ---- checkpoints ----------------------------------------------------------------------------
    _ARRAYS = ("done", "docking", "ko_flag", "ko_t", "ko_r", "closest")

    def snapshot(self) -> dict:
        return {name: getattr(self, name).tobytes() for name in self._ARRAYS}

    def restore(self, snap: dict) -> None:
        for name in self._ARRAYS:
            mine = getattr(self, name)
            mine[...] = np.frombuffer(snap[name], dtype=mine.dtype).reshape(mine.shape)
