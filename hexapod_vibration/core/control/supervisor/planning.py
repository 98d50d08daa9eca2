"""A set of setting changes checked as a whole, and what it leads to (nothing changed).

Each value is checked against its declaration by :class:`~.config.NotchConfig`; here what
depends on several settings or on what the supervisor knows: the oscillators (tones x
orders, at most :data:`~hexapod_vibration.parameter_specs.MAX_NOTCH_TONES`, every order below
fs/2 over the whole tracking range, one reference order per tone), the update low-pass
fixed at start-up (``update_lowpass_hz``, and with -1 whether the tones move), and the
stability bound on ``mu`` of the resulting tones and mode (the
identified plant at those tones, else the normalised bound): a change of ``adaptation`` or
of the tones is refused too if it would leave the present ``mu`` unstable. ``mu = 0`` (no
adaptation) is always stable.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexapod_vibration.core.control.notch import validate_frequencies
from hexapod_vibration.core.control.supervisor.config import NotchConfig, Settings
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge
from hexapod_vibration.core.control.supervisor.rate_policy import RatePolicy
from hexapod_vibration.parameter_specs import (
    MAX_NOTCH_TONES,
    UPDATE_LOWPASS_AUTO,
    update_lowpass_corner_hz,
)

RETUNING_SETTINGS = ("tone_frequencies_hz", "adaptation", "harmonics")
"""Settings whose change needs new coefficients and a new bound."""
BOUNDED_SETTINGS = ("mu", *RETUNING_SETTINGS)
"""Settings whose change is refused when it leaves ``mu`` at or above the bound."""


@dataclass(frozen=True)
class Plan:
    """A checked set of changes: the settings, oscillators, mode, known response, P, bound."""

    config: NotchConfig
    tones: list[float]
    mode: str
    response: np.ndarray | None
    coefficients: np.ndarray | None
    bound: float


def bank_frequencies(tones_hz: np.ndarray | list[float], harmonics: int) -> np.ndarray:
    """Every oscillator's frequency (Hz): orders 1..harmonics+1 of each tone, order-major.

    Row ``k * T + t`` of the bank is order ``k + 1`` of tone ``t`` (T tones).
    """
    tones = np.asarray(tones_hz, dtype=float).reshape(-1)
    orders = np.arange(1, int(harmonics) + 2, dtype=float)
    return (orders[:, None] * tones[None, :]).reshape(-1)


def oscillators(config: NotchConfig, sample_rate_hz: float) -> list[float]:
    """The oscillators (Hz) of ``config``; ValueError if the settings do not go together."""
    tones = np.asarray(config.tone_frequencies_hz, dtype=float)
    harmonics = config.harmonics
    orders = int(harmonics) + 1
    if tones.size * orders > MAX_NOTCH_TONES:
        raise ValueError(f"{tones.size} tones x {orders} orders (harmonics={harmonics}) "
                         f"= {tones.size * orders} oscillators: at most {MAX_NOTCH_TONES}")
    reach = tones + (float(config.tracking_range_hz) if config.frequency_tracking else 0.0)
    if tones.size and orders * reach.max() >= 0.5 * sample_rate_hz:
        raise ValueError(f"order {orders} of {tones[np.argmax(reach)]:g} Hz (tracked up "
                         f"to {reach.max():g} Hz) reaches fs/2 = {0.5 * sample_rate_hz:g} Hz")
    ref = np.asarray(config.reference_harmonics, dtype=float)
    if ref.size and ref.size != tones.size:
        raise ValueError(f"reference_harmonics needs one order per tone ({tones.size}), "
                         f"got {ref.size}")
    bank = bank_frequencies(tones, harmonics)
    try:
        validate_frequencies(bank, sample_rate_hz)
    except ValueError as exc:
        raise ValueError(f"harmonics={harmonics} rejected: {exc}") from None
    return bank.tolist()


def check_update_lowpass_in_force(config: NotchConfig, present: NotchConfig,
                                  corner_hz: float) -> None:
    """ValueError unless ``config`` asks for the update low-pass in force (``corner_hz``, Hz).

    It is fixed at start-up (the stability bound and the prediction were computed with
    it): a new ``update_lowpass_hz`` is refused, and with -1 (automatic) so is a change
    that would move the tones where they were fixed, or fix them where they moved.
    """
    if config.update_lowpass_hz != present.update_lowpass_hz:
        raise ValueError("update_lowpass_hz is set at start-up (the stability bound and "
                         "the prediction were computed with "
                         f"{present.update_lowpass_hz:g} Hz)")
    wanted = update_lowpass_corner_hz(vars(config))
    if wanted == corner_hz:
        return
    what = ("frequency_tracking" if config.frequency_tracking != present.frequency_tracking
            else "reference_harmonics")
    raise ValueError(f"{what}: with update_lowpass_hz {UPDATE_LOWPASS_AUTO:g} (automatic) "
                     f"these tones would adapt with a {wanted:g} Hz update low-pass, but the "
                     f"one in force is {corner_hz:g} Hz, chosen at start-up (the stability "
                     "bound and the prediction were computed with it): start the node with "
                     f"{what} set so, or with update_lowpass_hz set")


def plan_changes(settings: Settings, changes: Mapping[str, Any], mu_in_force: float,
                 plant: PlantKnowledge, rates: RatePolicy) -> Plan:
    """Check ``changes`` (parameter name -> value) against the settings in force.

    Raises:
        KeyError: a name that is not a notch setting.
        ValueError: the reason to refuse the changes (one line).
    """
    present = settings.config
    config = present.replaced(changes)
    tones = oscillators(config, settings.fs)
    check_update_lowpass_in_force(config, present, settings.update_lowpass_hz)
    mode = config.adaptation
    if any(name in changes for name in RETUNING_SETTINGS):
        response = plant.known_response(tones)
        try:
            coefficients, bound = rates.coefficients_for(tones, response, mode)
        except ValueError as exc:
            raise ValueError(f"adaptation={mode!r} rejected: {exc}") from None
    else:
        response, coefficients, bound = plant.response, None, rates.bound
    mu = changes.get("mu", mu_in_force)
    if mu > 0.0 and mu >= bound and any(name in changes for name in BOUNDED_SETTINGS):
        raise ValueError(f"mu={mu:g} is outside the stability bound {bound:.4g} ({mode} "
                         f"adaptation at {tones} Hz, eq. 18 with a "
                         f"{present.loop_delay_samples:g}-sample loop delay)")
    return Plan(config, tones, mode, response, coefficients, bound)
