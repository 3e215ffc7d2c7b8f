"""The second gyro's bias in ``canest calibrate``: the first gyro's, as fitted, less the two gyros' mean difference.

Two gyros on one body read one yaw rate, so ``r_m - r_m2 = b_r - b_r2`` at every tick; the output-error fit
(:mod:`canest.models.output_error`) gives ``b_r`` from the car's motion, and the second gyro's (an airbag unit's)
follows as ``b_r2 = b_r - mean(r_m - r_m2)``, as the online calibration learns it
(:meth:`canest.estimation.online_calibration.OnlineCalibration._gyros_update`). Only steady ticks are averaged
(the yaw rate changing by less than ``MAX_YAW_ACCELERATION`` over ``SPAN``): the two gyros' frames sample the yaw
rate apart in time, which in a swerve is a difference of several deg/s. The mean's interval is the differences'
spread over the square root of their number, widened by their correlation in time, in quadrature with the fitted
``b_r``'s; its correlation with the other parameters is ``b_r``'s, scaled.
"""
from __future__ import annotations

import numpy as np

from canest.calibration import CONFIDENCE, MAX_YAW_ACCELERATION, Fit, widening

SPAN = 0.4  # s over which a tick's yaw acceleration is taken (the 50 Hz gyro's noise, differenced tick to tick, is
# 0.1 rad/s^2 on the simulator)
MIN_TICKS = 50  # steady ticks with both gyros below which the second gyro's bias is not given


def steady_differences(drive) -> np.ndarray:
    """``r_m - r_m2`` of the drive's ticks with both gyros whose yaw rate changes by less than
    ``MAX_YAW_ACCELERATION`` over ``SPAN`` centred on them, within one stretch."""
    if drive.yaw_rate_2 is None or len(drive.t) < 3:
        return np.empty(0)
    half = max(1, int(round(0.5 * SPAN / float(np.median(np.diff(drive.t))))))
    stretch = np.cumsum(drive.starts)
    k = np.arange(half, len(drive.t) - half)
    same = (stretch[k - half] == stretch[k + half])
    rate = np.abs(drive.yaw_rate[k + half] - drive.yaw_rate[k - half]) / (drive.t[k + half] - drive.t[k - half])
    difference = drive.yaw_rate[k] - drive.yaw_rate_2[k]
    return difference[same & (rate < MAX_YAW_ACCELERATION) & np.isfinite(difference)]


def with_second_gyro(fit: Fit, drives) -> Fit:
    """``fit`` with ``gyro_bias_2`` appended (module docstring), or unchanged where the drives have fewer than
    ``MIN_TICKS`` steady ticks with both gyros (a car with one)."""
    differences = [d for d in (steady_differences(drive) for drive in drives) if d.size]
    if sum(d.size for d in differences) < MIN_TICKS:
        return fit
    pooled = np.concatenate(differences)
    mean_std = float(np.std(pooled)) / np.sqrt(pooled.size) * max(widening(d) for d in differences)
    first = fit.names.index("gyro_bias")
    first_std = fit.half_widths[first] / CONFIDENCE
    std = float(np.hypot(first_std, mean_std))
    row = fit.correlation[first] * (first_std / std if std > 0.0 else 0.0)
    n = len(fit.names)
    correlation = np.eye(n + 1)
    correlation[:n, :n] = fit.correlation
    correlation[n, :n] = correlation[:n, n] = row
    return Fit([*fit.names, "gyro_bias_2"], np.append(fit.values, fit.values[first] - float(np.mean(pooled))),
               np.append(fit.half_widths, CONFIDENCE * std), correlation, fit.rms, fit.seconds)
