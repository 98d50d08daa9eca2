"""``/pph/*_forecast``: a controller publishes its next commands, a realtime driver takes them.

The controller's end (:class:`ForecastPublisher`) publishes, every
``FORECAST_EVERY_SAMPLES`` (each controller at its own phase, ``FORECAST_PHASE_SAMPLES``)
and only while a subscriber listens (a realtime driver), once its loop is idle after the
sample's answer (:mod:`~hexapod_vibration.core.loop.idle_work`), the
commands of its next ``FORECAST_SAMPLES`` samples: the notch controller's sinusoids
(:mod:`hexapod_vibration.core.control.command_forecast`), the pointing controller's last
commands continued (:mod:`hexapod_vibration.core.control.tone_continuation`: they oscillate
with the shaker's tone; zero force instead, the watchdog's, is a step of tens of N). The
driver's end (:func:`subscribe_forecasts`) checks each message (its bytes, label, whole
rows of six, finite values) and hands the rows and run to the arbiter, which applies one
when the command of its sample is late; a bad one is refused with a throttled warning and
changes nothing. A loop subscription of the driver (raw, every wake-up).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from rclpy.node import Node
from rclpy.subscription import Subscription
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.cdr import encode_vector_cdr
from hexapod_vibration.contract import (
    FORECAST_EVERY_SAMPLES,
    FORECAST_ROWS_LABEL,
    FORECAST_SAMPLES,
    STRUT_COUNT,
    InvalidStrutMessage,
)
from hexapod_vibration.core.control.command_forecast import WeightTrend, notch_forecast
from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor
from hexapod_vibration.core.loop.idle_work import IdleWork
from hexapod_vibration.ros.messages import (
    create_parsed_subscription,
    parse_labelled_sample,
)
from hexapod_vibration.ros.qos import LOOP_QOS
from hexapod_vibration.ros.rclpy_internals import serialized_publish


class ForecastPublisher:
    """A controller's forecasts on ``topic``, published while someone listens."""

    def __init__(self, node: Node, topic: str, phase_samples: int,
                 rows: Callable[[int], np.ndarray], idle_work: IdleWork,
                 last_acted: Callable[[], tuple[int, int | None]]) -> None:
        """Create the publisher (:data:`~hexapod_vibration.ros.qos.LOOP_QOS`).

        ``phase_samples``: forecast after the samples ``n`` with ``n %
        FORECAST_EVERY_SAMPLES == phase_samples`` (:data:`~hexapod_vibration.contract.
        FORECAST_PHASE_SAMPLES`: the two controllers on different samples). ``rows(k)``: the
        controller's next ``k`` commands (N, (k, 6)) after the last sample it took.
        ``idle_work``: the node's deferred work, where the forecast waits for an idle loop.
        ``last_acted()``: ``(index, run)`` of that last sample (the controller's
        :meth:`~hexapod_vibration.ros.messages.ControllerLoopPort.last_acted`).
        """
        self._publisher = node.create_publisher(Float64MultiArray, topic, LOOP_QOS)
        self._publish = serialized_publish(self._publisher)       # CDR bytes
        self._phase = phase_samples
        self._rows = rows
        self._idle_work = idle_work
        self._last_acted = last_acted

    def after(self, index: int) -> None:
        """Sample ``index`` was answered: every 10th, a forecast when the loop is idle."""
        if ((index - self._phase) % FORECAST_EVERY_SAMPLES
                or not self._publisher.get_subscription_count()):
            return
        self._idle_work.defer(self.publish)

    def publish(self) -> None:
        """``rows(FORECAST_SAMPLES)`` after the last sample taken, published now.

        Computed from the controller's state when it runs: samples answered since the
        forecast was asked for are in that state, and the first row is the sample after
        them.
        """
        index, run = self._last_acted()
        self._publish(encode_vector_cdr(self._rows(FORECAST_SAMPLES).reshape(-1), index + 1,
                                        run, label=FORECAST_ROWS_LABEL))


def notch_rows(supervisor: NotchSupervisor) -> Callable[[int], np.ndarray]:
    """The notch controller's forecast, as :meth:`ForecastPublisher.after` asks for it.

    :func:`~hexapod_vibration.core.control.command_forecast.notch_forecast` of the
    supervisor's canceller (its weights moving at their trend) and running identification.
    """
    trend = WeightTrend()

    def rows(samples: int) -> np.ndarray:
        canceller = supervisor.canceller
        rate = trend.rate(canceller.weights, supervisor.last_sample)
        return notch_forecast(canceller, supervisor.identification.identifier, samples, rate)
    return rows


def parse_forecast(msg: Float64MultiArray) -> tuple[np.ndarray, int, int | None]:
    """``(rows (K, 6) N, first sample, run)`` of a ``/pph/*_forecast`` message.

    Raises:
        InvalidStrutMessage: another label, no sample label, not whole rows of six, none,
            or a non-finite value.
    """
    sample = parse_labelled_sample(msg, FORECAST_ROWS_LABEL, STRUT_COUNT)
    if sample.values.size == 0:
        raise InvalidStrutMessage("a forecast without a row")
    return sample.values.reshape(-1, STRUT_COUNT), sample.index, sample.run


def subscribe_forecasts(node: Node, topic: str,
                        on_forecast: Callable[[np.ndarray, int, int | None], None]
                        ) -> Subscription:
    """Subscribe ``node`` to ``topic``; ``on_forecast(rows, first, run)`` for each good one.

    Returns the (raw) subscription, for the node's loop subscriptions.
    """
    return create_parsed_subscription(node, topic, parse_forecast, on_forecast, LOOP_QOS)
