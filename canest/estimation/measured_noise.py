"""A sensor's noise as its samples show it: what a filter must take for an IMU that vibrates.

The configured noise of an IMU channel is its datasheet's (the built-in
config: gyro 0.002 rad/s, ay 0.11 m/s^2 with a road's crown; the model's error beside it grows with ay). An
IMU on a real body also vibrates: the simulator's ``vibration 1``, as the
issue's real car, moves ay by 1.4 m/s^2 and the gyro by 0.3 deg/s,
correlated over 15 ms. Taken at the configured noise, on the honesty grid
(``tools/honesty.py --vibration 1``, built-in config, every filter, 3 seeds):
the yaw rate was 2.7 times too certain (within 2 std 50-69 %, NEES 4.3-9.9,
valid but wrong 0.3-0.7 % of ticks) and vx 2-4 times (58-78 %, NEES 4-14,
valid but wrong 1.4-2.9 %), and the consistency test could not see the
gyro's part: a coloured noise that the prior has followed leaves small
innovations. The filters also trusted ay ten times too much, which moved
their yaw rate and vx.

:class:`MeasuredNoise` reads the noise from the samples alone, without any
model. The last ``3 span`` s of samples are cut into three spans; the middle
span's mean is compared with the straight line through the outer two's (at
their mean times: a slope cancels, what is left is the noise and the
signal's curvature over the spans). Squared, over what a white noise of unit
variance gives there (``1/n_1 + w_0^2/n_0 + w_2^2/n_2``, ``n`` the spans'
samples, ``w`` the interpolation weights), it is the variance of the white
noise that would scatter the spans' means as much, averaged over ``MEMORY``
s (:attr:`MeasuredNoise.std`; times the sampling period, the noise's
density, :attr:`MeasuredNoise.density`). Means, not single samples, because a
filter averages a few samples: the mean of three 10 ms samples of a noise
correlated over 15 ms has 1.9 times the variance a white noise of the same
variance gives it, and it is that scatter the estimate carries. A channel
sampled more sparsely than two samples a span gets spans of ``PER_SPAN``
sampling periods (a 20 Hz gyro: 75 ms).

The estimator (:mod:`canest.estimation.core`) takes it six ways, never
below the configured values, so a quiet sensor changes nothing: an
accelerometer channel's R (ax, ay; the consistency test takes it too, but
friction's and the divergence test keep the configured noise,
:mod:`canest.estimation.validity`; the
published ``InnovationNis`` is the filter's, with the R it used); the published yaw
rate's std, times the gyro's measured noise over the noise the filter's covariance took for it (the
configured, or an adaptive filter's learned R where larger: :meth:`canest.estimation.core.Estimator._gyro_noise`;
:meth:`canest.estimation.judge.StateJudge.widen`), which with the hold's factor
(:meth:`canest.estimation.gyro_hold.GyroHold.noise_factor`) the yaw rate's consistency test also judges the
gyro under (:meth:`canest.estimation.judge.StateJudge.record`), and the two-track model's yaw acceleration, the gyro's slope,
by the slope of the gyro's noise beyond the configured (its R:
:meth:`canest.estimation.two_track.FrictionEstimator._yaw_acceleration_noise`); vx's process noise where
vx integrates the measured ax; and the reference speed's std while it
integrates ax (:mod:`canest.estimation.reference_speed`), both from ax's
density over 0.1 s spans (:data:`canest.estimation.core.INTEGRATED_NOISE_SPAN`; the
random walk it puts into the reference speed is in that channel's std or,
where the model integrates ax, in the filter's prior: vx's consistency test
sees it either way); and the kinematic sideslip check's tolerance, from ay's
density over the same spans where ay is louder than configured (:class:`canest.estimation.validity.KinematicCheck`).
The gyro's noise is not its R: in a slide (the DLC on friction 0.35) the
yaw rate's own fast changes read as noise, and svd-fckf, whose adaptive R
may grow to ten times the R it is given, stopped following its gyro (yaw
rate RMSE 0.17 -> 0.53 deg/s on that drive; over the clean grid 0.127 ->
0.191).

``SPAN``, measured on three drives of the simulator (``ckf``; DLC, sine and
step on 0.85), with the yaw rate's published std scaled by the measured
over the configured gyro noise:

| span | clean: noise read (white 0.1 deg/s), NEES | vibrating: noise read, NEES, within 2 std |
|---|---|---|
| single samples, 30 ms apart | 0.104-0.109 deg/s, 1.0-1.26 | 0.29-0.30 deg/s, 1.10-1.34, 92-94 % |
| 20 ms | 0.103-0.107, 1.0-1.27 | 0.28-0.29, 1.44-1.85, 88-92 % |
| 30 ms (``SPAN``) | 0.106-0.115, 0.96-1.14 | 0.35-0.36, 1.11-1.45, 93-96 % |
| 40 ms | 0.114-0.146, 0.68-0.97 | 0.40-0.42, 0.98-1.25, 95-96 % |

Longer spans read more of a car's own motion on a clean drive (the DLC's at
40 ms: 0.146 deg/s). Nothing is told before ``WARMUP`` s of residuals: the
honesty grid's drives are 8-15 s, and waiting for a full ``MEMORY`` left
their first seconds at NEES 7.
"""
from __future__ import annotations

import math
from collections import deque

SPAN = 0.03  # s of samples per mean
MEMORY = 2.0  # s over which the squared residuals are averaged (exponentially)
WARMUP = 0.25  # s of residuals before the noise is told (their mean so far)
PER_SPAN = 1.5  # sampling periods per span at least: a 20 Hz channel's 30 ms spans would often hold no sample
PERIOD_SAMPLES = 20  # samples over which the sampling period is averaged


class MeasuredNoise:
    """One channel's noise standard deviation from its samples (module docstring)."""

    def __init__(self, span: float = SPAN):
        self.span = span  # s per mean at least; a sparser channel's spans hold PER_SPAN of its sampling periods
        self.samples = deque()
        self.reset()

    def reset(self) -> None:
        self.samples.clear()
        self.variance = None  # mean squared normalized residual, None before the first residual
        self.seen = 0.0  # s of residuals averaged, up to MEMORY
        self.period = None  # s between samples, averaged over the last PERIOD_SAMPLES

    def add(self, t: float, value: float) -> None:
        """One new sample taken at ``t`` (s); a sample older than the last starts over, a non-finite one is left
        out (the decoder rejects them; this keeps one from poisoning the mean for good). After a gap longer than
        ``MEMORY`` it starts over too."""
        if not (math.isfinite(t) and math.isfinite(value)) or (self.samples and t == self.samples[-1][0]):
            return
        if self.samples and not 0.0 < t - self.samples[-1][0] <= MEMORY:
            self.reset()  # time ran backwards (a replay looped) or a gap: what was measured is another stretch's
        if self.samples:
            step = t - self.samples[-1][0]
            self.period = step if self.period is None else self.period + (step - self.period) / PERIOD_SAMPLES
        self.samples.append((t, value))
        if self.period is None:
            return
        width = max(self.span, PER_SPAN * self.period)
        start = t - 3.0 * width
        if self.samples[0][0] > start + 0.5 * width:
            return  # the first span is not yet covered
        while self.samples[0][0] < start:
            self.samples.popleft()
        spans = [[], [], []]
        for sample in self.samples:
            spans[min(int((sample[0] - start) / width), 2)].append(sample)
        if not all(spans):
            return
        counts = [len(span) for span in spans]
        times = [sum(s[0] for s in span) / len(span) for span in spans]
        means = [sum(s[1] for s in span) / len(span) for span in spans]
        w_first, w_last = (times[2] - times[1]) / (times[2] - times[0]), (times[1] - times[0]) / (times[2] - times[0])
        residual = means[1] - (w_first * means[0] + w_last * means[2])
        white = 1.0 / counts[1] + w_first * w_first / counts[0] + w_last * w_last / counts[2]
        self.seen = min(self.seen + step, MEMORY)  # a mean over all until MEMORY s, then exponential
        square = residual * residual / white
        self.variance = square if self.variance is None else self.variance + step / self.seen * (square - self.variance)

    @property
    def std(self) -> float | None:
        """The measured noise standard deviation, None until ``WARMUP`` s of residuals were averaged."""
        return math.sqrt(self.variance) if self.variance is not None and self.seen >= WARMUP else None

    @property
    def density(self) -> float | None:
        """The noise's spectral density at the span's time scale (unit^2 s: a white noise's variance times its
        sampling period), None until ``WARMUP`` s of residuals were averaged."""
        return self.variance * self.period if self.std is not None else None
