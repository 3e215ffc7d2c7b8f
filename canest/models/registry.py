"""Vehicle models by the name a config gives in ``estimator.model``."""
from canest.models.single_track import SingleTrackModel
from canest.models.tire_force import TireForceModel
from canest.models.two_track import TwoTrackModel

MODELS = {"single_track": SingleTrackModel, "tire_force": TireForceModel, "two_track": TwoTrackModel}
