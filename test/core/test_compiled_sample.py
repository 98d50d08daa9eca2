"""The compiled kernels step the plant to the same numbers as its NumPy path, bit for bit.

The claim of core/model/compiled_sample.py: the same element-wise operations in the same
order and the same BLAS routines, so the two paths are equal, not close. (A platform whose
NumPy and SciPy link different BLAS libraries could round a product differently: this test
would then say so.) The plain reference implementation of every sample is
test_plant_speed_equivalence.py's, run on both paths.
"""

import numpy as np
import pytest
from kernel_calls import numba_files_called

from hexapod_vibration.core.model import kernel_choice
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import PPHPlant
from hexapod_vibration.core.model.shaker import Shaker, tones_from_arrays
from hexapod_vibration.paths import config_path

pytest.importorskip("numba")

CFG = load_model_config(config_path("pph_model.yaml"))
FIELDS = ("accel_m_s2", "eddy_m", "applied_force_n", "top_accel_true", "relative_pose_true",
          "stroke_m")


def _plant(monkeypatch, kernels: str, model) -> PPHPlant:
    monkeypatch.setenv(kernel_choice.KERNELS_ENV, kernels)
    tones = tones_from_arrays([40.0, 80.0, 120.0], [80.0, 16.0, 12.0])     # paper Table 1
    return PPHPlant(model, shaker=Shaker(tones, 0.5, 100.0, seed=3), seed=4)


def _commands(samples: int) -> np.ndarray:
    """Table 1-sized forces, a free-play burst, a push onto the stops, then NaN (N)."""
    n = np.arange(samples)[:, None]
    sine = np.sin(2 * np.pi * 40 * n / 1000) * np.ones(6)
    burst = (150 <= n) & (n < 180)
    push = (350 <= n) & (n < 550)
    commands = (3.0 * sine + 38.0 * sine * burst * np.array([1, -1, 1, -1, 1, -1.0])
                + 70.0 * np.sign(np.sin(2 * np.pi * 12 * n / 1000)) * push)
    commands[-3:] = np.nan                      # NaN passes both paths alike
    return commands


@pytest.mark.parametrize("nonlinear", [True, False])
def test_the_compiled_plant_equals_the_numpy_plant(monkeypatch, nonlinear):
    model = CFG if nonlinear else CFG.linear()
    compiled, numpy_path = _plant(monkeypatch, "compiled", model), _plant(monkeypatch, "numpy",
                                                                         model)
    assert compiled._kernels is not None and numpy_path._kernels is None
    for command in _commands(800):
        a, b = compiled.step(command), numpy_path.step(command)
        for field in FIELDS:
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    assert compiled.fallback_samples == numpy_path.fallback_samples
    assert compiled.accelerometers.clipped_samples == numpy_path.accelerometers.clipped_samples
    if nonlinear:
        assert compiled.fallback_samples > 0 and compiled.accelerometers.clipped_samples > 0
    for a, b in ((compiled.shaker, numpy_path.shaker), (compiled.eddy, numpy_path.eddy),
                 (compiled.accelerometers, numpy_path.accelerometers)):
        assert a._rng.random() == b._rng.random()          # the noise streams are in step


def test_the_environment_chooses_the_numpy_path(monkeypatch):
    monkeypatch.setenv(kernel_choice.KERNELS_ENV, " NumPy ")
    assert kernel_choice.compiled_kernels() is None
    assert kernel_choice.compiled_law_kernels() is None
    assert kernel_choice.compiled_continuation_kernels() is None
    assert kernel_choice.kernels_name(None) == "numpy"
    monkeypatch.delenv(kernel_choice.KERNELS_ENV)
    kernels = kernel_choice.compiled_kernels()
    assert kernels is not None and kernel_choice.kernels_name(kernels) == "compiled"
    assert kernel_choice.compiled_law_kernels() is not None
    assert kernel_choice.compiled_continuation_kernels() is not None
    plant = PPHPlant(CFG)
    assert plant.kernels == "compiled"
    assert plant.shaker._kernels is kernels and plant.accelerometers._kernels is kernels


def test_no_python_runs_inside_a_kernel(monkeypatch):
    """No Python code runs inside a kernel call, so a Ctrl-C cannot land in one.

    A kernel that returned an array ran numba's ``_numba_unpickle`` (Python) to box it: a
    Ctrl-C there raised the nodes' StopSignal inside the kernel, which numba turned into a
    SystemError (a driver exited 1, not 130). The kernels return numbers only.
    """
    plant = _plant(monkeypatch, "compiled", CFG)
    plant.step(np.ones(6))              # the first sample lays out the shaker's grid
    # free-play, stops (the NumPy fallback) and NaN
    assert not numba_files_called(lambda: [plant.step(c) for c in _commands(600)])
