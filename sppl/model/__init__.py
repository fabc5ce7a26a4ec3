"""What a model is: its classes and their priors, the scene hypothesis (a trace), the sensors'
likelihoods, the region, and draws from it all.

A model file compiles to a ``Model`` (``sppl.load_model``); the same model can be built in
Python from the types exported here (docs/api.md shows one).
"""

from .distributions import (
                            Beta,
                            Categorical,
                            DiscreteUniform,
                            Exponential,
                            Gamma,
                            LogNormal,
                            Normal,
                            Poisson,
                            TruncatedNormal,
                            Uniform,
)
from .domains import Finite, Integer, Interval, Periodic, Positive, Real
from .geometry import Part, rotation, rotation_z, scaling, translation
from .types import InferenceSettings, Model, ObjectClass, Parameter, RenderSettings, Sensor

__all__ = [
    "Beta",
    "Categorical",
    "DiscreteUniform",
    "Exponential",
    "Finite",
    "Gamma",
    "InferenceSettings",
    "Integer",
    "Interval",
    "LogNormal",
    "Model",
    "Normal",
    "ObjectClass",
    "Parameter",
    "Part",
    "Periodic",
    "Poisson",
    "Positive",
    "Real",
    "RenderSettings",
    "Sensor",
    "TruncatedNormal",
    "Uniform",
    "rotation",
    "rotation_z",
    "scaling",
    "translation",
]
