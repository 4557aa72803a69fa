"""Control delay: the delay between the controller output and the force."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayes_amb.discrepancy.library.base import (
    Candidate,
    EffectEntry,
    Equivalence,
    Quantity,
    Sampled,
    zoh_scaled,
)
from bayes_amb.inference.priors import Prior

PRIOR_TEXT = "U(0, max(4 dt, 0.4 ms))"


@dataclass(frozen=True)
class TimeDelay(Candidate):
    """Control delay between the commanded current and the force, any fraction of samples,
    exact under ZOH: x[k+1] = Ad x[k] + G(dt - f) u[k-m] + e^{A(dt-f)} G(f) u[k-m-1] for a
    delay m dt + f. Sampled: delay in ms (null 0), up to 4 samples or 0.4 ms."""

    own_sampling = True

    def max_delay_ms(self, ctx):
        return max(4 * ctx.dt, 4e-4) * 1e3

    def params(self, ctx):
        return tuple(s.at(self.location, Prior("uniform", 0.0, self.max_delay_ms(ctx)))
                     for s in self.entry.sampled)

    def structure(self, phi, ctx):
        d = np.clip(phi[:, 0], 0.0, None) * 1e-3
        return np.floor(d / ctx.dt + 1e-12).astype(int)

    def discretise(self, A, B, phi, ctx):
        dt = ctx.dt
        d = np.clip(phi[:, 0], 0.0, None) * 1e-3
        m_all = np.floor(d / dt + 1e-12).astype(int)
        if np.any(m_all != m_all[0]):
            raise ValueError("rows of one batch must share the integer delay")
        m = int(m_all[0])
        f = d - m * dt                                               # (nb,) in [0, dt)
        nb, n, nu = B.shape
        E1, G_now = zoh_scaled(A, B, dt - f)
        _, G_f = zoh_scaled(A, B, f)
        Ad, _ = zoh_scaled(A, B, np.full(nb, dt))
        G_prev = E1 @ G_f
        slots = m + 1                                                # u[k-1] .. u[k-m-1]
        N = n + nu * slots
        A_aug = np.zeros((nb, N, N))
        B_aug = np.zeros((nb, N, nu))
        A_aug[:, :n, :n] = Ad
        if m == 0:
            B_aug[:, :n] = G_now
        else:
            A_aug[:, :n, n + nu * (m - 1):n + nu * m] = G_now
        A_aug[:, :n, n + nu * m:n + nu * (m + 1)] = G_prev
        B_aug[:, n:n + nu] = np.eye(nu)
        for s in range(1, slots):                                    # shift register
            A_aug[:, n + nu * s:n + nu * (s + 1), n + nu * (s - 1):n + nu * s] = np.eye(nu)
        E = np.zeros((nb, N, n))
        E[:, :n, :n] = np.eye(n)
        return A_aug, B_aug, E

    def physical(self, draws, ctx):
        return {"delay_s": (np.clip(draws[:, 0], 0.0, None) * 1e-3, "s")}

    def describe(self, values):
        return f"control delay {values['delay_s'] * 1e6:.1f} us"


ENTRY = EffectEntry(
    name="time_delay", title="control delay (actuator side)",
    description=("delay between the controller output and the force (computation, PWM, "
                 "amplifier), any fraction of a sample"),
    fingerprint=("phase lag growing linearly with frequency, no change of magnitude, on "
                 "every channel"),
    side="actuator", locations=("controller",),
    sampled=(Sampled("delay_ms", Prior("uniform", 0.0, 0.4), 0.0, "ms", "delay",
                     PRIOR_TEXT),),
    physical=(Quantity("delay_s", "s", "delay"),),
    equivalences=(Equivalence("*", "sensor_delay@sensors", "same delay: a delay common to "
                              "all channels commutes with G"),),
    make=lambda loc: TimeDelay("time_delay", loc))
TimeDelay.entry = ENTRY
