"""The CAN hand proxy driver: a LeafSystem with the simulated hand driver's ports.

:class:`CanHandProxy` talks to the CAN bus server through a
:class:`~handle_drake.can_hand.client.CanHandClient` (a background thread),
so its periodic update only swaps arrays under a lock and never waits on the
network. :func:`AddCanHandDriver` adds it to a builder and exports the
station's ``hand.*`` ports.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from handle_drake.can_hand.client import STREAMING, CanHandClient
from handle_drake.can_hand.config import CanHandDriverConfig
from handle_drake.can_hand.layout import HandLayout, hand_layout

__all__ = ["CanHandProxy", "AddCanHandDriver", "STATION_SIGNALS"]

#: The ``hand.<signal>`` outputs every hand driver exports (the station's contract).
STATION_SIGNALS = ("position_commanded", "position_measured", "velocity_estimated",
                   "state_estimated", "tactile")


class CanHandProxy(LeafSystem):
    """Drives a CAN hand through the CAN bus server; same ports as the simulated driver.

    Every ``config.period`` seconds it sends the ``position`` input (if the
    input has a value) and copies the newest hand state into its discrete
    state. Until the first state arrives it outputs ``initial_position``;
    while disconnected it holds the last measured positions with zero
    velocity, and the client reconnects by itself.

    Ports (``nu`` actuated joints, ``nq`` joints, ``nt`` fingertips; order of
    :class:`~handle_drake.can_hand.layout.HandLayout`):

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
        nq, nu, nt = layout.nq, layout.nu, layout.num_tactile
        if initial_position is None:
            q0 = np.clip(np.zeros(nu), layout.command_lower, layout.command_upper)
        else:
            q0 = np.asarray(initial_position, dtype=float)
            if q0.shape != (nu,):
                raise ValueError(f"initial_position: expected {nu} values, got shape {q0.shape}")
            if not np.all(np.isfinite(q0)):
                raise ValueError(f"initial_position: expected finite values, got {q0.tolist()}")
        x0 = np.concatenate([layout.joint_positions(q0), np.zeros(nq), np.zeros(nt), q0, [0.0]])
        self._slices = {
            "q": slice(0, nq), "v": slice(nq, 2 * nq), "tactile": slice(2 * nq, 2 * nq + nt),
            "commanded": slice(2 * nq + nt, 2 * nq + nt + nu), "connection": slice(-1, None),
        }
        self._state_index = self.DeclareDiscreteState(x0)
        self._command_port = self.DeclareVectorInputPort("position", nu)
        self.DeclareVectorOutputPort("position_commanded", nu, self._output("commanded"),
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort("position_measured", nq, self._output("q"),
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort("velocity_estimated", nq, self._output("v"),
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort("state_estimated", 2 * nq, self._calc_state,
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort("tactile", nt, self._output("tactile"),
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort("connection_state", 1, self._output("connection"),
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclarePeriodicDiscreteUpdateEvent(config.period, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        self._client = client or CanHandClient(
            layout, config.host, config.port, connect_timeout=config.connect_timeout,
            reconnect_interval=config.reconnect_interval, status_timeout=config.status_timeout,
            realtime_priority=config.realtime_priority)
        self._client.start()

    # -- accessors -----------------------------------------------------------
    @property
    def client(self) -> CanHandClient:
        return self._client

    def get_command_input_port(self):
        return self._command_port

    def close(self) -> None:
        """Stops the client thread (the system must not be simulated afterwards)."""
        self._client.close()

    # -- calculations ---------------------------------------------------------
    def _output(self, key):
        index = self._slices[key]

        def calc(context, output: BasicVector):
            output.SetFromVector(context.get_discrete_state(self._state_index).value()[index])

        return calc

    def _calc_state(self, context, output: BasicVector):
        x = context.get_discrete_state(self._state_index).value()
        output.SetFromVector(x[:2 * self.layout.nq])

    def _update(self, context, discrete_state):
        s = self._slices
        x = context.get_discrete_state(self._state_index).value().copy()
        if self._command_port.HasValue(context):
            command = self._command_port.Eval(context)
            if not np.all(np.isfinite(command)):
                raise ValueError(
                    "CanHandProxy: input 'position' must be finite, got "
                    f"{np.asarray(command).tolist()}"
                )
            self._client.send_command(command)
        state, _ = self._client.latest()
        connection = self._client.connection_state
        if state is not None:
            x[s["q"]] = state.q
            x[s["v"]] = state.v
            x[s["tactile"]] = state.tactile
            x[s["commanded"]] = state.setpoint
        if connection != STREAMING:
            x[s["v"]] = 0.0  # holding the last measurement: nothing is known to move
        x[s["connection"]] = connection
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(x)


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
        builder.ExportInput(driver.get_command_input_port(), f"{model_name}.position")
        for signal in STATION_SIGNALS:
            builder.ExportOutput(driver.GetOutputPort(signal), f"{model_name}.{signal}")
    return driver
