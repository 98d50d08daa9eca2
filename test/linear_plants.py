"""Linear discrete-time test plants shared by the canceller and adaptation tests."""

import numpy as np
from scipy import signal
from scipy.linalg import block_diag

FS = 1000.0


def resonance_bank(f_res_hz, zeta, gain):
    """(A, B, C) at FS of one resonance g w^2/(s^2 + 2 zeta w s + w^2) per channel.

    ZOH discretisation of a strictly proper system: a command of sample n reaches the
    output from sample n+1 on, as in docs/architecture.md.
    """
    blocks = []
    for f in np.atleast_1d(f_res_hz):
        w = 2 * np.pi * f
        ss = signal.tf2ss([gain * w * w], [1.0, 2 * zeta * w, w * w])
        blocks.append(signal.cont2discrete(ss, 1 / FS, method="zoh")[:3])
    return tuple(block_diag(*m) for m in zip(*blocks, strict=True))


def frequency_response(plant, freqs_hz):
    """G[t] = C (e^{jw} I - A)^{-1} B: phasor of e per unit phasor of u."""
    a, b, c = plant
    eye = np.eye(a.shape[0])
    return np.stack([c @ np.linalg.solve(np.exp(2j * np.pi * f / FS) * eye - a, b)
                     for f in np.atleast_1d(freqs_hz)])


def simulate(plant, controller, dist, on_sample=None):
    """Closed loop e_n = C x_n + d_n, u_n = controller(e_n), x_{n+1} = A x_n + B u_n."""
    a, b, c = plant
    x = np.zeros(a.shape[0])
    errors = np.empty_like(dist)
    for n in range(dist.shape[0]):
        e = c @ x + dist[n]
        errors[n] = e
        u = controller.step(e)
        x = a @ x + b @ u
        if on_sample is not None:
            on_sample(n)
    return errors


def simulate_with_gaps(plant, controller, dist, missing, sent=None):
    """:func:`simulate` with samples the controller never receives (``missing[n]``).

    The controller is told of them (``skip``) with the next sample it gets; the plant holds
    the previous command over a missing sample, as the driver holds a late one, unless
    ``sent(n)`` gives the command that went out all the same.
    """
    a, b, c = plant
    x, u, pending = np.zeros(a.shape[0]), np.zeros(b.shape[1]), 0
    for n in range(dist.shape[0]):
        e = c @ x + dist[n]
        if missing[n]:
            pending += 1
            if sent is not None:
                u = sent(n)
        else:
            if pending:
                controller.skip(pending)
                pending = 0
            u = controller.step(e)
        x = a @ x + b @ u
    if pending:
        controller.skip(pending)


def late_notch_rig(samples: int):
    """A notch supervisor on a coupled 6-strut plant, its driver's arbiter, late commands.

    The plant: six resonances, inputs mixed by a random 20 % coupling. The arbiter applies
    the answer to sample n at n+1 (``delay_samples`` 1). ``late[n]``: the command of sample
    n comes after its deadline (1 % single samples and stalls of 20 ms).

    Returns ``((a, b, c), supervisor, arbiter, late, rng)``, ``rng`` for what the test
    draws next (the shaker's noise).
    """
    from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
    from hexapod_vibration.core.loop.command_arbiter import CommandArbiter

    a, b, c = resonance_bank([22.0, 35.0, 48.0, 61.0, 95.0, 140.0], 0.05, 1.0)
    b = b @ (np.eye(6) + 0.2 * np.random.default_rng(3).normal(size=(6, 6)))
    supervisor = NotchSupervisor(NotchConfig().replaced(
        {"tone_frequencies_hz": [40.0], "identify_delay_s": 0.0}))
    arbiter = CommandArbiter(("notch",), (), 1, 1e3, delay_samples=1)
    arbiter.refresh_connections({"notch": 1}, 5)
    rng = np.random.default_rng(11)
    late = rng.random(samples) < 0.01
    for start in np.flatnonzero(rng.random(samples) < 0.0005):
        late[start:start + 20] = True                 # stalls of 20 ms
    return (a, b, c), supervisor, arbiter, late, rng
