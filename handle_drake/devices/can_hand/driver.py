"""The CAN hand proxy driver: a diagram with the simulated hand driver's ports.

:class:`CanHandProxy` is a transport (:class:`CanHandTransport`, the only
system that does I/O: it holds a
:class:`~handle_drake.devices.can_hand.client.CanHandClient`, a background thread,
sends the command and keeps the newest message in its state, never waiting
on the network) and a pure, stateless translator
(:class:`CanHandStatusReceiver`), as Drake's
``kuka_iiwa`` / ``schunk_wsg`` drivers split LCM from message translation.
:func:`AddCanHandDriver` adds it to a builder and exports the station's
``hand.*`` ports.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem

from handle_drake.base.port_names import HAND_COMMAND, HAND_SIGNALS
from handle_drake.devices.can_hand.client import DISCONNECTED, STREAMING, CanHandClient
from handle_drake.devices.can_hand.config import CanHandDriverConfig
from handle_drake.devices.can_hand.layout import HandLayout, hand_layout

__all__ = ["CanHandProxy", "CanHandTransport", "CanHandStatusReceiver", "feedback_layout",
           "AddCanHandDriver", "STATION_SIGNALS"]

#: The ``hand.<signal>`` outputs every hand driver exports (the station's contract,
#: :mod:`handle_drake.base.port_names`).
STATION_SIGNALS = HAND_SIGNALS


def feedback_layout(layout: HandLayout) -> dict[str, slice]:
    """Where each field sits in the feedback vector between transport and receiver:
    ``q`` (nq), ``v`` (nq), ``tactile`` (nt), ``setpoint`` (nu), ``connection`` (1)."""
    nq, nu, nt = layout.nq, layout.nu, layout.num_tactile
    return {"q": slice(0, nq), "v": slice(nq, 2 * nq), "tactile": slice(2 * nq, 2 * nq + nt),
            "setpoint": slice(2 * nq + nt, 2 * nq + nt + nu),
            "connection": slice(2 * nq + nt + nu, 2 * nq + nt + nu + 1)}


class CanHandTransport(LeafSystem):
    """The transport, and the only part that does I/O: a started :class:`CanHandClient`.

    Ports: input ``command`` (nu, rad); output ``feedback``: the newest hand
    cycle received, as a vector laid out by :func:`feedback_layout` (the last
    one is kept until a newer arrives; before the first, ``initial_position``
    at rest), with the link's connection state. Every ``period`` (and at
    initialization) one update queues the command (if the input has a value; it
    must be finite) and copies the client's newest message into the state, as
    Drake's LCM subscriber systems keep the last message. Neither waits: the
    client (a background thread) only swaps data under a lock. Sending and
    receiving in events of their own (Drake's LCM publisher and subscriber
    systems) costs more Python events every 2 ms: a first version with separate
    events fell behind real time on the loaded 2-core machine (the end-to-end
    lag test read 41 ms against its 64 ms physical minimum), so one update does
    both, at the old single system's cost per period. The client is made and
    started by its owner (:class:`CanHandProxy`), not here.
    """

    def __init__(self, client: CanHandClient, initial_position, period: float):
        super().__init__()
        self._client = client
        layout = client.layout
        self._slices = feedback_layout(layout)
        q0 = np.asarray(initial_position, dtype=float)
        x0 = np.concatenate([layout.joint_positions(q0), np.zeros(layout.nq),
                             np.zeros(layout.num_tactile), q0, [DISCONNECTED]])
        self._command_port = self.DeclareVectorInputPort("command", layout.nu)
        self._state_index = self.DeclareDiscreteState(x0)
        self.DeclareStateOutputPort("feedback", self._state_index)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)

    @property
    def client(self) -> CanHandClient:
        return self._client

    def get_command_input_port(self):
        return self._command_port

    def _update(self, context, discrete_state):
        if self._command_port.HasValue(context):
            command = self._command_port.Eval(context)
            if not np.all(np.isfinite(command)):
                raise ValueError(
                    "CanHandProxy: input 'position' must be finite, got "
                    f"{np.asarray(command).tolist()}"
                )
            self._client.send_command(command)
        s = self._slices
        x = context.get_discrete_state(self._state_index).value().copy()
        message, _ = self._client.latest()
        if message is not None:
            x[s["q"]] = message.q
            x[s["v"]] = message.v
            x[s["tactile"]] = message.tactile
            x[s["setpoint"]] = message.setpoint
        x[s["connection"]] = self._client.connection_state
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(x)


class CanHandStatusReceiver(LeafSystem):
    """Translates the transport's feedback into the station's ``hand.*`` signals (pure:
    no I/O, no state; a function of its input).

    While the link is not streaming the velocities read zero: the held last
    measurement says nothing about motion.

    Ports (``nu`` actuated joints, ``nq`` joints, ``nt`` fingertips; order of
    :class:`~handle_drake.devices.can_hand.layout.HandLayout`): input ``feedback``
    (:func:`feedback_layout`); outputs ``position_commanded`` (nu, rad),
    ``position_measured`` (nq, rad), ``velocity_estimated`` (nq, rad/s),
    ``state_estimated`` (2 nq), ``tactile`` (nt, N), ``connection_state`` (1).
    """

    def __init__(self, layout: HandLayout):
        super().__init__()
        self.layout = layout
        self._slices = s = feedback_layout(layout)
        nq, nu, nt = layout.nq, layout.nu, layout.num_tactile
        self._feedback = self.DeclareVectorInputPort("feedback", s["connection"].stop)
        for name, key, size in (("position_commanded", "setpoint", nu),
                                ("position_measured", "q", nq)):
            self.DeclareVectorOutputPort(name, size, self._copy(key))
        self.DeclareVectorOutputPort("velocity_estimated", nq, self._calc_velocity)
        self.DeclareVectorOutputPort("state_estimated", 2 * nq, self._calc_state)
        self.DeclareVectorOutputPort("tactile", nt, self._copy("tactile"))
        self.DeclareVectorOutputPort("connection_state", 1, self._copy("connection"))

    def _copy(self, key):
        index = self._slices[key]

        def calc(context, output: BasicVector):
            output.SetFromVector(self._feedback.Eval(context)[index])

        return calc

    def _velocity(self, x) -> np.ndarray:
        s = self._slices
        return x[s["v"]] if x[s["connection"]][0] == STREAMING else np.zeros(self.layout.nq)

    def _calc_velocity(self, context, output: BasicVector):
        output.SetFromVector(self._velocity(self._feedback.Eval(context)))

    def _calc_state(self, context, output: BasicVector):
        x = self._feedback.Eval(context)
        output.SetFromVector(np.concatenate([x[self._slices["q"]], self._velocity(x)]))


class CanHandProxy(Diagram):
    """Drives a CAN hand through the CAN bus server; same ports as the simulated driver.

    Two parts, as Drake's hardware drivers are built: the transport
    (:class:`CanHandTransport`: the client, sends the ``position`` input and
    fetches the newest hand state every ``config.period`` seconds) and a pure
    translator (:class:`CanHandStatusReceiver`). Until the first state arrives
    it outputs ``initial_position``; while disconnected it holds the last
    measured positions with zero velocity, and the client reconnects by
    itself. The client is given, or made from ``config`` and started here.

    Ports (``nu`` actuated joints, ``nq`` joints, ``nt`` fingertips; order of
    :class:`~handle_drake.devices.can_hand.layout.HandLayout`):

    - input ``position`` (nu, rad): joint position command, actuated order
      (Barrett: ``f1_spread f1_prox f2_prox f3_prox``, F1 being the finger at
      x < 0 of the palm, as on the real hand).
    - output ``position_commanded`` (nu, rad): the setpoint the hand is
      tracking (after the server's clamping and rate limits).
    - output ``position_measured`` (nq, rad): all joints.
    - output ``velocity_estimated`` (nq, rad/s): filtered finite differences
      (zero while not streaming).
    - output ``state_estimated`` (2 nq): positions then velocities.
    - output ``tactile`` (nt, N): normal force on each fingertip pad.
    - output ``connection_state`` (1): 0 disconnected, 1 connected without
      fresh hand data, 2 streaming.
    """

    def __init__(self, layout: HandLayout, config: CanHandDriverConfig | None = None,
                 initial_position=None, client: CanHandClient | None = None):
        super().__init__()
        if not isinstance(layout, HandLayout):
            raise TypeError(f"layout: expected a HandLayout, got {type(layout).__name__}")
        config = config or CanHandDriverConfig()
        config.validate()
        if config.hand_kind and config.hand_kind != layout.kind:
            raise ValueError(f"hand_kind: the driver is configured for a {config.hand_kind} "
                             f"hand, got a {layout.kind} hand")
        self.layout, self.config = layout, config
        if initial_position is None:
            q0 = np.clip(np.zeros(layout.nu), layout.command_lower, layout.command_upper)
        else:
            q0 = np.asarray(initial_position, dtype=float)
            if q0.shape != (layout.nu,):
                raise ValueError(f"initial_position: expected {layout.nu} values, got shape "
                                 f"{q0.shape}")
            if not np.all(np.isfinite(q0)):
                raise ValueError(f"initial_position: expected finite values, got {q0.tolist()}")
        if client is None:
            client = CanHandClient(
                layout, config.host, config.port, connect_timeout=config.connect_timeout,
                reconnect_interval=config.reconnect_interval,
                status_timeout=config.status_timeout,
                realtime_priority=config.realtime_priority).start()
        self._client = client
        builder = DiagramBuilder()
        transport = builder.AddNamedSystem("transport",
                                           CanHandTransport(client, q0, config.period))
        receiver = builder.AddNamedSystem("status_receiver", CanHandStatusReceiver(layout))
        builder.Connect(transport.GetOutputPort("feedback"), receiver.GetInputPort("feedback"))
        builder.ExportInput(transport.get_command_input_port(), "position")
        for i in range(receiver.num_output_ports()):
            port = receiver.get_output_port(i)
            builder.ExportOutput(port, port.get_name())
        builder.BuildInto(self)

    # -- accessors -----------------------------------------------------------
    @property
    def client(self) -> CanHandClient:
        return self._client

    def get_command_input_port(self):
        return self.GetInputPort("position")

    def close(self) -> None:
        """Stops the client thread (the system must not be simulated afterwards)."""
        self._client.close()


def AddCanHandDriver(builder, config: CanHandDriverConfig, hand_spec, *,
                     coupling_ratio: float | None = None, initial_position=None,
                     model_name: str = "hand", system_name: str = "hand_driver",
                     export: bool = True) -> CanHandProxy:
    """Adds a :class:`CanHandProxy` to ``builder`` and exports the station's hand ports.

    Args:
        builder: a DiagramBuilder.
        config: the scenario's CAN driver settings.
        hand_spec: a ``HandSpec``, a hand kind ("shadow", "barrett") or a
            :class:`HandLayout`.
        coupling_ratio: the Shadow distal coupling (ignored for a layout).
        initial_position: nu command entries output until the hand reports.
        model_name: prefix of the exported ports.
        export: export ``<model_name>.position`` (input) and the
            :data:`STATION_SIGNALS` outputs, like the simulated station.

    Returns:
        The driver; its ``connection_state`` output is not exported (the
        simulated station has no such port).
    """
    layout = hand_spec if isinstance(hand_spec, HandLayout) else hand_layout(hand_spec,
                                                                             coupling_ratio)
    driver = builder.AddNamedSystem(system_name, CanHandProxy(layout, config, initial_position))
    if export:
        builder.ExportInput(driver.get_command_input_port(), f"{model_name}.{HAND_COMMAND}")
        for signal in STATION_SIGNALS:
            builder.ExportOutput(driver.GetOutputPort(signal), f"{model_name}.{signal}")
    return driver
