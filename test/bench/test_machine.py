"""The bench's machine record says what steps the plant, as the nodes it starts will choose."""

from hexapod_vibration.bench.machine import machine_info, machine_summary
from hexapod_vibration.core.model.kernel_choice import KERNELS_ENV


def test_the_machine_record_names_the_plants_kernels(monkeypatch):
    monkeypatch.setenv(KERNELS_ENV, "numpy")
    info = machine_info()
    assert info["plant_kernels"] == "numpy"
    assert "plant kernels numpy" in machine_summary(info)
    monkeypatch.delenv(KERNELS_ENV)
    assert machine_info()["plant_kernels"] == "compiled"      # numba is in requirements.txt
