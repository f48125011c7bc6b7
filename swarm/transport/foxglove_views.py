"""The swarm as Foxglove sees it (issue 16): the raw channel of every key, and views in Foxglove's
well-known schemas, logged to a ``foxglove.Context`` whose sinks are a live WebSocket server
(``swarm foxglove``) or an MCAP file.

* every key: a channel of that topic, ``message_encoding`` ``msgpack`` with a schema named after its message
  type (``tpods.Truth``; empty: docs/protocol.md is the schema), the payload byte for byte;
* ``/tf`` (``foxglove.FrameTransforms``): each vehicle's true pose (frame ``<id>/truth``) and estimated pose
  (``<id>/estimate``) in frame ``nav``, from its ``truth`` and ``estimate`` messages, at most
  ``tf_rate_hz`` per frame (a view for the eye; every sample is in the raw channels);
* ``/events`` (``foxglove.Log``): every event, the vehicle's or the run's, as a log line;
* ``/scene`` (``foxglove.SceneUpdate``): the UWB anchors as spheres in ``nav``.

Log time is swarm time (:func:`swarm.transport.recording.swarm_time_ns`). A sample that does not decode is
still logged on its raw channel, and drives no view.
"""

from __future__ import annotations

import warnings

from swarm.transport.keys import Keys
from swarm.transport.messages import (
    MESSAGE_FOR_KIND,
    Anchors,
    DropCounter,
    Estimate,
    Event,
    Truth,
    safe_decode,
)

with warnings.catch_warnings():
    warnings.simplefilter("ignore", DeprecationWarning)
    import foxglove
    from foxglove.channels import FrameTransformsChannel, LogChannel, SceneUpdateChannel
    from foxglove.messages import (
        Color,
        FrameTransform,
        FrameTransforms,
        Log,
        LogLevel,
        Pose,
        Quaternion,
        SceneEntity,
        SceneUpdate,
        SpherePrimitive,
        Timestamp,
        Vector3,
    )

VIEW_TOPICS = ("/tf", "/events", "/scene")


def _ts(ns: int) -> Timestamp:
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


class SwarmViews:
    """Log a swarm's samples (key, payload, swarm time) on Foxglove channels of ``context`` (module
    docstring)."""

    def __init__(self, context: foxglove.Context, keys: Keys, tf_rate_hz: float = 20.0) -> None:
        self.ctx, self.keys = context, keys
        self.tf_period_ns = round(1e9 / tf_rate_hz)
        self._tf_last: dict[str, int] = {}
        self.raw: dict[str, foxglove.Channel] = {}
        self.tf = FrameTransformsChannel("/tf", context=context)
        self.events = LogChannel("/events", context=context)
        self.scene = SceneUpdateChannel("/scene", context=context)
        self.drops = DropCounter()

    def handle(self, key: str, payload: bytes, log_time_ns: int) -> None:
        parsed = self.keys.parse(key)
        ch = self.raw.get(key)
        if ch is None:  # schemaless msgpack: its schema's name is the message type (docs/protocol.md)
            cls = MESSAGE_FOR_KIND.get(parsed[0]) if parsed else None
            schema = foxglove.Schema(
                name=f"tpods.{cls.__name__ if cls else 'msgpack'}", encoding="", data=b""
            )
            ch = self.raw[key] = foxglove.Channel(
                key, message_encoding="msgpack", schema=schema, context=self.ctx
            )
        ch.log(payload, log_time=log_time_ns)
        if parsed is None or parsed[0] not in MESSAGE_FOR_KIND:
            return
        kind, vid = parsed
        if kind in ("truth", "estimate"):
            last = self._tf_last.get(key)
            if last is not None and 0 <= log_time_ns - last < self.tf_period_ns:
                return  # decimated: the view at tf_rate_hz
            self._tf_last[key] = log_time_ns
            msg = safe_decode(payload, Truth if kind == "truth" else Estimate, key, self.drops)
            if msg is not None:
                p, q = msg.p_nav, msg.q_nav_body
                tf = FrameTransform(
                    timestamp=_ts(log_time_ns), parent_frame_id="nav", child_frame_id=f"{vid}/{kind}",
                    translation=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                    rotation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
                )  # fmt: skip
                self.tf.log(FrameTransforms(transforms=[tf]), log_time=log_time_ns)
        elif kind in ("event", "world_event"):
            ev = safe_decode(payload, Event, key, self.drops)
            if ev is not None:
                level = (
                    LogLevel.Warning
                    if ev.kind in ("abort", "collision", "lost", "keepout_violation")
                    else LogLevel.Info
                )
                self.events.log(Log(timestamp=_ts(log_time_ns), level=level, message=f"{ev.kind}: {ev.data}",
                                    name=vid or "world", file="", line=0), log_time=log_time_ns)  # fmt: skip
        elif kind == "anchors":
            a = safe_decode(payload, Anchors, key, self.drops)
            if a is not None:
                level_q = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
                size = Vector3(x=0.05, y=0.05, z=0.05)
                orange = Color(r=1.0, g=0.3, b=0.0, a=1.0)
                spheres = [
                    SpherePrimitive(pose=Pose(position=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                                              orientation=level_q), size=size, color=orange)
                    for p in a.positions_nav
                ]  # fmt: skip
                ent = SceneEntity(timestamp=_ts(log_time_ns), frame_id="nav", id="anchors", spheres=spheres)
                self.scene.log(SceneUpdate(entities=[ent]), log_time=log_time_ns)
