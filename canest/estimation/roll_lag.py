"""The accelerations the wheel loads follow: ax as measured, ay through the body's roll lag.

The loads of eq 7 (DICI-GFCKF; :meth:`canest.models.wheels.WheelGeometry.loads`)
move left and right with the body's roll, which a vibrating accelerometer's
15 ms shakes and road spikes do not move; taken from each ay sample, the
vibration moved lateral force between an axle's two wheels, a split that no
measurement row sees (the two wheels' forces act at the same moment arm), so
no covariance held it either: on the vibrating honesty grid dici-gfckf's rear
left force fell from 1 612 to 826 N in 30 ms on the step (true 1 612) while
the rear right rose by as much, 4 std off. A first-order lag::

    ay_load[k] = ay_load[k-1] + alpha (ay[k] - ay_load[k-1]),   alpha = dt / (ROLL_LAG + dt)

(an e-folding time of ``-dt / ln(1 - alpha)``, 0.055 s at 100 Hz; the
simulator's suspension lags its load transfer by 0.08 s,
``canest.sim.plant.LOAD_TRANSFER_TAU``; a passenger car's roll mode answers
in about that time). A stale ay, or one at its DBC limit, passes as 0 (the
held inputs' value for no measurement) and the next good sample starts the
lag anew. Only ay is lagged: ax also drives the longitudinal forces and vx,
and the front-rear split it moves is seen by the yaw moment.
"""
from __future__ import annotations

from canest.estimation.inputs import TickInputs
from canest.estimation.lags import FirstOrderLag

ROLL_LAG = 0.05  # s: below the simulator's 0.08, README "How far to trust the output" measured 0.05 and 0.1


def accelerations(inputs: TickInputs) -> tuple[float, float]:
    """(ax, ay) as held, 0 where stale or at its DBC limit (the two-track model's loads take them so: the roll lag
    was measured there and not kept, README "How far to trust the output")."""
    return inputs.current("ax"), inputs.current("ay")


class LoadAccelerations:
    """(ax, ay) as the wheel loads take them: ax as held (:func:`accelerations`), ay :data:`ROLL_LAG` behind the
    measured, starting at the first sample (after a :meth:`reset`: the estimator's, or a stale ay)."""

    def __init__(self, dt: float):
        self.ay_lag = FirstOrderLag(dt, ROLL_LAG)

    def reset(self) -> None:
        self.ay_lag.reset()

    def update(self, inputs: TickInputs) -> tuple[float, float]:
        ax, ay = accelerations(inputs)
        if not inputs.has("ay"):
            self.ay_lag.reset()  # stale or at its DBC limit (0): the next good sample starts anew
            return ax, ay
        return ax, self.ay_lag.update(ay)
