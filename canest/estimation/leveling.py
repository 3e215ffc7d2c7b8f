"""Accelerometer samples read level: the body's roll and pitch taken out of ax and ay.

An ESC fixed to the body reads part of gravity as the body rolls in bends and pitches as it accelerates
(:mod:`canest.models.attitude`): 4 deg/g of roll makes ay read 7 % high, which the online calibration's
kinematic identity (``ay = s v r``) cannot tell from a 7 % larger wheel, and which the filters read as a
larger lateral force. With the config's ``vehicle.accelerometer_roll_gradient`` and
``accelerometer_pitch_gradient`` (deg/g; 0, the default: the ESC publishes them level) each tick's ay and
ax (and the second IMU's) are read level before the online calibration and the filters see them
(:class:`canest.pipeline.Pipeline`, and ``canest calibrate``'s :func:`canest.apps.drive_signals.read_drive`).
"""
from __future__ import annotations

import dataclasses

from canest.models.attitude import level_reading, per_si
from canest.params import VehicleParams

AXES = {"ax": "pitch", "ax_2": "pitch", "ay": "roll", "ay_2": "roll"}  # input -> the tilt its axis shares


class AccelerometerLeveling:
    def __init__(self, vehicle: VehicleParams, names):
        gradients = {"roll": per_si(vehicle.accelerometer_roll_gradient),
                     "pitch": per_si(vehicle.accelerometer_pitch_gradient)}
        self.tilted = [(i, gradients[AXES[name]]) for i, name in enumerate(names)
                       if name in AXES and gradients[AXES[name]] > 0.0]

    def level(self, sample):
        """``sample`` with its accelerometers read level (itself when the config says they are)."""
        if not self.tilted:
            return sample
        values = sample.values.copy()
        for index, gradient in self.tilted:
            values[index] = level_reading(values[index], gradient)
        return dataclasses.replace(sample, values=values)
