"""canest: online vehicle state estimation on CAN.

Frames in through a DBC, a nonlinear Kalman filter on a vehicle model, estimates
out through a DBC. See README.md for the data flow.
"""

__version__ = "0.1.0"
