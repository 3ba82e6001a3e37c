"""The inverse problem: fit a PlateModel's parameters to a measured AFC (:func:`identify`)."""

from vibid.identify.fit.inputs import Measurement, ModelChoice, SearchOptions
from vibid.identify.fit.strategy import identify

__all__ = ["Measurement", "ModelChoice", "SearchOptions", "identify"]
