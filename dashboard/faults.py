"""The dashboard's Faults panel: inject a run-time fault (issue 7) from the browser, as ``swarm fault`` does
from a shell, and see what the world and the mothership made of it.

The panel's inputs (:class:`FaultForm`, GUI units) become a :class:`~swarm.transport.messages.Fault`
through :func:`fault_of`, which keeps only the inputs the chosen kind uses and lets the ``Fault`` message
validate them: the same checks every receiver applies, no second validator. A refused value is reported
with the panel input's label, the wire field and the value (``duration [s] (duration_s): must be > 0, got
-1.0``) and nothing is published. A valid fault goes out on ``<ns>/control/fault``; the world (camera, gyro,
sensor delay) and the mothership (UWB) answer with ``fault`` events when they apply it, the world with a
``fault_refused`` event when it cannot (a ``sensor_delay`` in a lockstep run, a vehicle it does not know,
a camera loss on a vehicle without a camera); the panel lists both (:func:`dashboard.panels.faults_markdown`).

What the panel offers follows the world it talks to (:class:`FaultMenu`): the kinds are the mission's
(:attr:`swarm.missions.Mission.fault_menu`), the words its drawer's (:meth:`dashboard.drawer.MissionDrawer.
fault_menu`: a docking swarm's in :mod:`dashboard.docking`, a landing swarm's in :mod:`dashboard.landing`).

:func:`fault_of` and :func:`kind_hint` are pure (tested without a server); :class:`FaultPanel` is the Viser
side.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import viser

from dashboard import panels
from dashboard.state import Snapshot
from swarm.errors import ConfigError, MessageError
from swarm.transport.messages import Fault

__all__ = [
    "EVERY_CHASER", "FAULT_INPUTS", "FaultForm", "FaultMenu", "FaultPanel", "fault_of", "kind_hint",
    "sent_text",
]  # fmt: skip

_LOG = logging.getLogger("dashboard.faults")

EVERY_CHASER = "every chaser"
"""The vehicle choice that sends ``vehicle = None`` (the world applies the fault to every chaser)."""

FAULT_INPUTS: dict[str, tuple[str, ...]] = {
    "uwb_dropout": ("duration", "start"),
    "nlos_burst": ("duration", "start", "probability"),
    "camera_loss": ("vehicle", "duration", "start"),
    "gyro_bias_step": ("vehicle", "start", "rate"),
    "sensor_delay": ("vehicle", "duration", "start", "delay"),
}
"""The panel inputs each fault kind uses (the others are hidden and not sent). UWB faults have no vehicle:
the mothership applies them to the whole radio network."""

LABELS: dict[str, str] = {
    "vehicle": "vehicle",
    "duration": "duration [s]",
    "start": "start at t [s]",
    "probability": "NLOS probability",
    "rate": "gyro step [deg/s]",
    "delay": "max delay [s]",
}
"""The label of each panel input."""

_INPUT_OF_FIELD = {
    "vehicle": "vehicle", "duration_s": "duration", "start_s": "start", "probability": "probability",
    "rate_rad_s": "rate", "delay_s": "delay",
}  # fmt: skip


@dataclass(frozen=True)
class FaultMenu:
    """The faults a world takes, as the panel offers them."""

    kinds: tuple[str, ...]
    """Each kind offered, in the panel's order: the mission's ``fault_menu``."""
    hints: Mapping[str, str]
    """One line per kind on what it does and who applies it."""
    every: str
    """The vehicle choice that sends ``vehicle = None``."""
    uwb_network: bool
    """Whether a UWB fault acts on the whole radio network (a docking swarm's, applied to every vehicle
    whatever the vehicle choice) rather than on the vehicles it names (a landing swarm's)."""
    appliers: str
    """Who announces a fault applied, as the panel's sent line says it."""

    @property
    def inputs(self) -> dict[str, tuple[str, ...]]:
        """Each kind offered and the inputs it uses (:data:`FAULT_INPUTS`; the others hidden and not sent),
        a vehicle too when a UWB fault acts on the vehicles it names (not ``uwb_network``)."""
        named = lambda uses: uses if self.uwb_network or "vehicle" in uses else ("vehicle", *uses)  # noqa: E731
        return {kind: named(FAULT_INPUTS[kind]) for kind in self.kinds}


@dataclass(frozen=True)
class FaultForm:
    """What the panel's inputs hold, in the panel's units."""

    kind: str
    """One of :data:`~swarm.transport.messages.FAULT_KINDS`."""
    vehicle: str = EVERY_CHASER
    """A vehicle id, or the menu's ``every`` (:data:`EVERY_CHASER`, a landing swarm's "every UAV")."""
    duration_s: object = 5.0
    """Length of the window [s] (the GUI's number; validated by ``Fault``)."""
    start_s: object = 0.0
    """Simulated time the window opens [s]; 0 means at once (the receiver's next tick)."""
    probability: object = 0.2
    """``nlos_burst``: outlier probability in (0, 1]."""
    rate_deg_s: Sequence[object] = (0.5, 0.0, 0.0)
    """``gyro_bias_step``: the added rate [deg/s], body frame."""
    delay_s: object = 0.05
    """``sensor_delay``: largest delay of a sample [s]."""


def _error(field: str, why: str) -> ConfigError:
    label = LABELS.get(_INPUT_OF_FIELD.get(field, ""), None)
    return ConfigError(f"{label} ({field}): {why}" if label else f"{field}: {why}")


def fault_of(form: FaultForm, menu: FaultMenu) -> Fault:
    """The :class:`Fault` the panel sends for ``form``: the inputs of its kind only (``menu.inputs``),
    ``start_s`` 0 as "at once", the gyro rate converted from deg/s to rad/s, validated by ``Fault`` itself.
    ConfigError naming the panel input, the wire field and the value, e.g. ``NLOS probability (probability):
    an nlos_burst needs one in (0, 1], got 1.5``; ConfigError for a kind the menu does not offer."""
    if form.kind not in menu.inputs:
        raise _error("kind", f"this world takes {', '.join(menu.inputs)}, got {form.kind!r}")
    uses = menu.inputs[form.kind]
    rate = None
    if "rate" in uses:
        try:
            rate = [math.radians(float(x)) for x in form.rate_deg_s]  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise _error("rate_rad_s", f"expected three numbers, got {form.rate_deg_s!r}") from None
    start = form.start_s if "start" in uses else None
    vehicle = form.vehicle if "vehicle" in uses and form.vehicle != menu.every else None
    try:
        return Fault(
            kind=form.kind,
            duration_s=form.duration_s if "duration" in uses else None,  # type: ignore[arg-type]
            start_s=None if start == 0 else start,  # type: ignore[arg-type]
            vehicle=vehicle,
            probability=form.probability if "probability" in uses else None,  # type: ignore[arg-type]
            rate_rad_s=rate,  # type: ignore[arg-type]
            delay_s=form.delay_s if "delay" in uses else None,  # type: ignore[arg-type]
        )
    except MessageError as exc:
        field, _, why = str(exc).partition(": ")
        raise _error(field, why) from None


def kind_hint(kind: str, clock_mode: str | None, menu: FaultMenu) -> str:
    """One line on what ``kind`` does, who applies it, and (``sensor_delay``) whether this run's clock,
    as the world announced it in ``run_start``, lets it."""
    text = f"_{menu.hints.get(kind, '')}._"
    if kind == "sensor_delay" and clock_mode == "lockstep":
        text += " **This run is lockstep: the world will refuse it.**"
    elif kind == "sensor_delay" and clock_mode is not None:
        text += f" This run's clock: {clock_mode}."
    return text


def sent_text(msg: Fault, listening: bool, at: str, menu: FaultMenu) -> str:
    """The panel's line after a fault was published at wall time ``at``."""
    network = menu.uwb_network and msg.kind in ("uwb_dropout", "nlos_burst")
    who = "" if network else f" on {msg.vehicle or menu.every}"
    dur = "" if msg.duration_s is None else f" for {msg.duration_s:g} s"
    head = f"sent **{msg.kind}**{who}{dur} at {at}"
    if not listening:
        return f"{head}, but nobody listens on control/fault (is the swarm up?)"
    return f"{head}: the {menu.appliers} lists it below once applied"


class FaultPanel:
    """The Faults folder of the GUI: kind, vehicle, the kind's parameters, Inject, the last action and the
    faults applied or refused. ``send`` publishes a :class:`Fault`; ``listening`` says whether anyone
    subscribes to ``control/fault``. With ``send=None`` (a recording's playback) the panel only lists the
    faults: its inputs and Inject are hidden. ``menu`` says which kinds the world takes (the mission drawer's
    :attr:`~dashboard.drawer.MissionDrawer.faults`)."""

    def __init__(
        self,
        gui: viser.GuiApi,
        send: Callable[[Fault], object] | None,
        listening: Callable[[], bool],
        vehicles: Sequence[str],
        menu: FaultMenu,
    ) -> None:
        self._send = send
        self.listening = listening
        self.menu = menu
        kinds = tuple(menu.inputs)
        first = "camera_loss" if "camera_loss" in kinds else kinds[0]
        with gui.add_folder("Faults"):
            self.kind = gui.add_dropdown("fault", kinds, initial_value=first)
            self.hint = gui.add_markdown(kind_hint(first, None, menu))
            options = [menu.every, *sorted(vehicles, key=panels.natural_key)]
            self.inputs: dict[str, viser.GuiInputHandle] = {
                "vehicle": gui.add_dropdown(LABELS["vehicle"], options, initial_value=menu.every),
                "duration": gui.add_number(LABELS["duration"], 5.0, step=0.1),
                "start": gui.add_number(LABELS["start"], 0.0, step=0.1, hint="0: at once"),
                "probability": gui.add_number(LABELS["probability"], 0.2, step=0.05),
                "rate": gui.add_vector3(LABELS["rate"], (0.5, 0.0, 0.0), step=0.1),
                "delay": gui.add_number(LABELS["delay"], 0.05, step=0.01),
            }  # fmt: skip
            self.button = gui.add_button("Inject", color="red")
            self.sent = gui.add_markdown("")
            self.log = gui.add_markdown(panels.faults_markdown((), uwb_network=menu.uwb_network))
        self._clock_mode: str | None = None
        self._faults_version: int | None = None
        self._show_inputs()
        if send is None:
            for handle in (self.kind, *self.inputs.values(), self.button):
                handle.visible = False
            self.hint.content = "a recording: the faults of the run as applied (none can be injected)"

        @self.kind.on_update
        def _(_event: object) -> None:
            self._show_inputs()

        @self.button.on_click
        def _(_event: object) -> None:
            self.inject()

    def _show_inputs(self) -> None:
        if self._send is None:
            return
        uses = self.menu.inputs.get(str(self.kind.value), ())
        for name, handle in self.inputs.items():
            if handle.visible != (name in uses):
                handle.visible = name in uses
        self.hint.content = kind_hint(str(self.kind.value), self._clock_mode, self.menu)

    def form(self) -> FaultForm:
        """The inputs as they are now."""
        v = {name: handle.value for name, handle in self.inputs.items()}
        return FaultForm(
            kind=str(self.kind.value), vehicle=str(v["vehicle"]), duration_s=v["duration"],
            start_s=v["start"], probability=v["probability"], rate_deg_s=tuple(v["rate"]), delay_s=v["delay"],
        )  # fmt: skip

    def inject(self, form: FaultForm | None = None) -> Fault | None:
        """What a click on Inject does: validate ``form`` (default: the inputs) and publish the fault, or
        say why not (and publish nothing). Returns the fault sent, or None."""
        form = self.form() if form is None else form
        at = time.strftime("%H:%M:%S")
        if self._send is None:
            self.sent.content = f"**not sent** ({at}): a recording is played, there is no swarm to send to"
            return None
        try:
            msg = fault_of(form, self.menu)
        except ConfigError as exc:
            self.sent.content = f"**not sent** ({at}): {exc}"
            _LOG.info("fault not sent: %s", exc)
            return None
        try:
            self._send(msg)
        except Exception as exc:  # a closed session at shutdown: say so, never raise into Viser
            self.sent.content = f"could not send {form.kind}: {exc}"
            _LOG.warning("could not send fault %s: %s", form.kind, exc)
            return None
        self.sent.content = sent_text(msg, self.listening(), at, self.menu)
        return msg

    def update(self, snap: Snapshot) -> None:
        """Vehicles seen for the first time join the vehicle choice; the hint follows the run's clock; the
        list follows the faults the world and the mothership announced."""
        vehicle = self.inputs["vehicle"]
        known = [o for o in vehicle.options if o != self.menu.every]  # type: ignore[attr-defined]
        if any(a not in known for a in snap.agents):
            ids = sorted(set(known) | set(snap.agents), key=panels.natural_key)
            vehicle.options = [self.menu.every, *ids]  # type: ignore[attr-defined]
        if snap.clock_mode != self._clock_mode and self._send is not None:
            self._clock_mode = snap.clock_mode
            self.hint.content = kind_hint(str(self.kind.value), self._clock_mode, self.menu)
        if snap.faults_version != self._faults_version:
            self._faults_version = snap.faults_version
            self.log.content = panels.faults_markdown(snap.faults, uwb_network=self.menu.uwb_network)

    def invalidate(self) -> None:
        """List the faults again at the next :meth:`update`."""
        self._faults_version = None
