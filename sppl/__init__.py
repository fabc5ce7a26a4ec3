"""sppl: Bayesian scene understanding with a small stochastic scene language.

The public API, for scripts and notebooks; the command line (``sppl``) is built on it:

    model = sppl.load_model("models/shapes.scn")
    obs = sppl.load_observations("examples/three_shapes/obs")
    result = sppl.run_chain(model, obs, Path("runs/three_shapes"), steps=2000, seed=0)
    result.summary["map"]

Everything heavier (the renderer's GL context, matplotlib for reports) is made only when used.
"""

from ._version import __version__  # noqa: F401  (sppl.__version__)
from .data.observations import Observations, load_cameras, load_observations, write_observations
from .errors import ModelError, ObservationError, RenderError, RunError, SpplError
from .infer.chain import Sampler
from .infer.moves import Proposal
from .lang import compile_model, load_model, parse
from .model import (
                    Beta,
                    Categorical,
                    DiscreteUniform,
                    Exponential,
                    Finite,
                    Gamma,
                    InferenceSettings,
                    Integer,
                    Interval,
                    LogNormal,
                    Normal,
                    ObjectClass,
                    Parameter,
                    Part,
                    Periodic,
                    Poisson,
                    Positive,
                    Real,
                    RenderSettings,
                    Sensor,
                    TruncatedNormal,
                    Uniform,
                    rotation,
                    rotation_z,
                    scaling,
                    translation,
)
from .model.gl_statistics import GlStatistics, register_gl_statistics, registered_gl_statistics
from .model.jumps import Jump, jump_names, register_jump, unregister_jump
from .model.likelihoods import Gaussian, Likelihood, available_likelihoods, register_likelihood
from .model.primitives import Hits, Primitive, primitive_names, register_primitive
from .model.region import RegionError, bind_region
from .model.robust import Mixture, StudentT
from .model.simulate import (
                    load_scene,
                    objects_from_dict,
                    render_observations,
                    sample_noise,
                    sample_objects,
)
from .model.trace import make_object
from .model.types import Model
from .output.compare import compare_scenes
from .output.posterior import load_run, open_posterior, write_posterior
from .output.report import (
                    CHAIN_COLOURS,
                    camera_figures,
                    evenly,
                    plot_occupancy,
                    pooled_samples,
                    write_report,
)
from .render import Renderer, raycast
from .render.seen import SeenPass, seen_reference
from .runs import experiment
from .runs.chains import run_chains
from .runs.dataset import find_scenes, run_dataset
from .runs.executors import LocalExecutor, RayExecutor
from .runs.run import run_chain
from .scoring.protocol import ObservationScorer, ScorerProtocol
from .scoring.scorer import PriorScorer, ReferenceScorer, Scorer
from .verify import check_proposals, joint_check, verify_model

__all__ = [
    "CHAIN_COLOURS",
    "Beta",
    "Categorical",
    "DiscreteUniform",
    "Exponential",
    "Finite",
    "Gamma",
    "Gaussian",
    "GlStatistics",
    "Hits",
    "InferenceSettings",
    "Integer",
    "Interval",
    "Jump",
    "Likelihood",
    "LocalExecutor",
    "LogNormal",
    "Mixture",
    "Model",
    "ModelError",
    "Normal",
    "ObjectClass",
    "ObservationError",
    "ObservationScorer",
    "Observations",
    "Parameter",
    "Part",
    "Periodic",
    "Poisson",
    "Positive",
    "Primitive",
    "PriorScorer",
    "Proposal",
    "RayExecutor",
    "Real",
    "ReferenceScorer",
    "RegionError",
    "RenderError",
    "RenderSettings",
    "Renderer",
    "RunError",
    "Sampler",
    "Scorer",
    "ScorerProtocol",
    "SeenPass",
    "Sensor",
    "SpplError",
    "StudentT",
    "TruncatedNormal",
    "Uniform",
    "available_likelihoods",
    "bind_region",
    "camera_figures",
    "check_proposals",
    "compare_scenes",
    "compile_model",
    "evenly",
    "experiment",
    "find_scenes",
    "joint_check",
    "jump_names",
    "load_cameras",
    "load_model",
    "load_observations",
    "load_run",
    "load_scene",
    "make_object",
    "objects_from_dict",
    "open_posterior",
    "parse",
    "plot_occupancy",
    "pooled_samples",
    "primitive_names",
    "raycast",
    "register_gl_statistics",
    "register_jump",
    "register_likelihood",
    "register_primitive",
    "registered_gl_statistics",
    "render_observations",
    "rotation",
    "rotation_z",
    "run_chain",
    "run_chains",
    "run_dataset",
    "sample_noise",
    "sample_objects",
    "scaling",
    "seen_reference",
    "translation",
    "unregister_jump",
    "verify_model",
    "write_observations",
    "write_posterior",
    "write_report",
]
