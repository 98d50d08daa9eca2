"""The physical range of every loop signal: beyond it a value is not a reading or a request.

A received ``/pph/*`` value outside its range cannot come from the hexapod (the sensors
clip or cannot see that far) nor be asked of it (the actuator amplifier's full scale), so
the receiving node refuses the whole message: counted on ``/diagnostics``, never applied
or adapted on.

- accel (m/s^2): the accelerometers clip at +-``range_g`` g (``config/pph_model.yaml``);
  a reading is in [-range, range - 1 LSB].
- eddy (m): the gaps follow the plate's motion relative to the bottom plate, which the six
  struts limit to their stroke: ``|gap_k| <= sum_i |(S J^-1)_ki| * stroke_limit``
  (S: gap sensing matrix, J: strut Jacobian), doubled for the hard stops' overtravel,
  the joints and the linearisation (35 mm * 2 for the packaged model).
- commands (N): the static force limit, the actuator's full scale. A notch command between
  the dynamic (40 N) and the static (70 N) limit is still accepted, and clipped by the
  driver exactly as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.sensors import G0_M_S2, EddySensorArray

EDDY_MARGIN = 2.0
"""Factor on the stroke-limited gap (hard-stop overtravel, joints, linearisation)."""


@dataclass(frozen=True)
class SignalRanges:
    """Largest magnitude of a value on each loop topic (SI units)."""

    accel_m_s2: float
    eddy_m: float
    command_n: float

    @classmethod
    def from_model(cls, model: ModelConfig) -> SignalRanges:
        """The ranges of the hexapod described by ``model``."""
        geometry = model.geometry
        sensing = EddySensorArray(model.eddy, float(geometry.top_joints_m[0, 2])).sensing_matrix
        gaps_per_stroke = np.abs(sensing @ np.linalg.inv(geometry.top_jacobian)).sum(axis=1)
        eddy = EDDY_MARGIN * float(gaps_per_stroke.max()) * model.strut.stroke_limit_m
        return cls(accel_m_s2=model.accelerometer.range_g * G0_M_S2, eddy_m=eddy,
                   command_n=model.strut.force_limit_static_n)


PYTHON_CHECK_MAX_VALUES = 16
"""Up to this many values (a strut message: 6) the check runs on the Python floats: about
1 us against 4 us for NumPy's reductions on this project's machine (four checks a sample
in the composed graph)."""


def out_of_range(values: np.ndarray, limit: float) -> str:
    """Why ``values`` are beyond ``+-limit`` ("" if every one is within), for diagnostics.

    A NaN is beyond any limit.
    """
    if values.size <= PYTHON_CHECK_MAX_VALUES:
        if all(-limit <= v <= limit for v in values.tolist()):
            return ""
    elif np.all(np.abs(values) <= limit):
        return ""
    worst = float(np.max(np.abs(values)))
    return f"|value| {worst:.6g} beyond the physical range {limit:.6g}"
