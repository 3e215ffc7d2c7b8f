"""Reference plant, driver, maneuvers and sensor models for tests and demos.

The plant is deliberately richer than the estimators' models (two-track,
Magic Formula tires with combined slip and load sensitivity, relaxation
length, lagged load transfer, wheel rotational dynamics driven by four motor
torques) so that estimation is always tested against a model mismatch.
"""
