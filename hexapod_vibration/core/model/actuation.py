"""The hexapod driven one loop sample at a time: commands summed, limited, held, stepped.

One routine for the ROS driver and the core loop alike (:class:`ActuatedPlant`): for loop
sample n the vibration command (N, with the actuator test sine added when it is on) and the
pointing command (N) are saturated to the actuators' limits (:func:`saturate_commands`),
held over [n/fs, (n+1)/fs) and the plant advances one sample; its sensors are then those
of sample n + 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.model.config import StrutConfig
from hexapod_vibration.core.model.plant import PlantSample, PPHPlant, saturate_commands


@dataclass
class TestSine:
    """The same sinusoid into all six actuators, added to the vibration command (Fig. 4)."""

    frequency_hz: float = 40.0
    amplitude_n: float = 0.0
    """Peak force (N); 0 is off."""

    def force_n(self, sample: int, sample_rate_hz: float) -> np.ndarray:
        """The sinusoid's force (N) on each actuator at loop sample ``sample``."""
        phase = 2.0 * np.pi * self.frequency_hz * sample / sample_rate_hz
        return np.full(6, self.amplitude_n * np.sin(phase))


class ActuatedPlant:
    """A :class:`PPHPlant` stepped with the loop's commands, one sample at a time.

    Args:
        plant: The plant (its shaker included).
        strut: Actuator limits (N).
        sample_rate_hz: Loop rate (Hz).
    """

    def __init__(self, plant: PPHPlant, strut: StrutConfig, sample_rate_hz: float) -> None:
        """Step the plant once with no force: the sensors of sample 0 are then pending."""
        self.plant = plant
        self.strut = strut
        self.sample_rate_hz = sample_rate_hz
        self.test_sine = TestSine()
        self.pending: PlantSample = plant.step(np.zeros(6))
        """The sensors of the sample the next :meth:`apply` is for."""

    def apply(self, sample: int, notch_n: np.ndarray, pointing_n: np.ndarray) -> np.ndarray:
        """Hold the commands of loop sample ``sample`` over it and advance the plant.

        Returns:
            The force (N) applied to each actuator after saturation.
        """
        if self.test_sine.amplitude_n > 0.0:
            notch_n = notch_n + self.test_sine.force_n(sample, self.sample_rate_hz)
        applied = saturate_commands(notch_n, pointing_n, self.strut)
        self.pending = self.plant.step(applied)
        return applied
