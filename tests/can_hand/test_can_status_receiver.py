"""CanHandStatusReceiver: the CAN hand's feedback as station signals, with no bus at all."""

import numpy as np

from handle_drake.devices.can_hand.client import CONNECTED, STREAMING
from handle_drake.devices.can_hand.driver import CanHandStatusReceiver, feedback_layout
from handle_drake.devices.can_hand.layout import hand_layout

PORTS = ("position_commanded", "position_measured", "velocity_estimated", "state_estimated",
         "tactile", "connection_state")


def _outputs(layout, feedback):
    receiver = CanHandStatusReceiver(layout)
    context = receiver.CreateDefaultContext()
    receiver.GetInputPort("feedback").FixValue(context, feedback)
    return {name: receiver.GetOutputPort(name).Eval(context) for name in PORTS}


def _feedback(layout, connection):
    s = feedback_layout(layout)
    x = np.zeros(s["connection"].stop)
    x[s["q"]] = 0.1 * np.arange(1.0, layout.nq + 1)
    x[s["v"]] = 0.5
    x[s["tactile"]] = 2.0
    x[s["setpoint"]] = 0.3 * np.arange(1.0, layout.nu + 1)
    x[s["connection"]] = connection
    return x, s


def test_streaming_feedback_is_every_field_in_the_layouts_order():
    layout = hand_layout("barrett")
    x, s = _feedback(layout, STREAMING)
    out = _outputs(layout, x)
    np.testing.assert_array_equal(out["position_measured"], x[s["q"]])
    np.testing.assert_array_equal(out["velocity_estimated"], x[s["v"]])
    np.testing.assert_array_equal(out["state_estimated"], np.concatenate([x[s["q"]],
                                                                          x[s["v"]]]))
    np.testing.assert_array_equal(out["tactile"], x[s["tactile"]])
    np.testing.assert_array_equal(out["position_commanded"], x[s["setpoint"]])
    assert out["connection_state"][0] == STREAMING


def test_a_held_measurement_without_streaming_reads_at_rest():
    layout = hand_layout("shadow")
    x, s = _feedback(layout, CONNECTED)
    out = _outputs(layout, x)
    np.testing.assert_array_equal(out["position_measured"], x[s["q"]])
    np.testing.assert_array_equal(out["velocity_estimated"], np.zeros(layout.nq))
    np.testing.assert_array_equal(out["state_estimated"][layout.nq:], np.zeros(layout.nq))
    assert out["connection_state"][0] == CONNECTED
