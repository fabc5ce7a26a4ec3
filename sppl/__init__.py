"""sppl: Bayesian scene understanding with a small stochastic scene language.

The public API, for scripts and notebooks; the command line (``sppl``) is built on it:

    model = sppl.load_model("models/shapes.scn")
    obs = sppl.load_observations("examples/three_shapes/obs")
    result = sppl.run_chain(model, obs, Path("runs/three_shapes"), steps=2000, seed=0)
    result.summary["map"]

Everything heavier (the renderer's GL context, matplotlib for reports) is made only when used.
"""

__version__ = "0.1.0"

from .chain import Sampler
from .compare import compare_scenes
from .dataset import find_scenes, run_dataset
from .errors import ModelError, ObservationError, RenderError, RunError, SpplError
from .lang import compile_model, load_model, parse
from .executors import LocalExecutor, RayExecutor
from .likelihoods import Gaussian, Likelihood, available_likelihoods, register_likelihood
from .model import Model
from .observations import Observations, load_cameras, load_observations, write_observations
from .posterior import load_run, open_posterior, write_posterior
from .proposal_checks import check_proposals, joint_check
from .region import RegionError, bind_region
from .render import Renderer, raycast
from .robust import Mixture, StudentT
from .run import run_chain, run_chains
from .scoring import ReferenceScorer, Scorer
from .seen import SeenPass, seen_reference
from .simulate import render_observations, sample_noise, sample_objects
from .verify import verify_model

__all__ = [
    "Gaussian",
    "Likelihood",
    "LocalExecutor",
    "Mixture",
    "Model",
    "ModelError",
    "ObservationError",
    "Observations",
    "RayExecutor",
    "ReferenceScorer",
    "RegionError",
    "RenderError",
    "Renderer",
    "RunError",
    "Sampler",
    "Scorer",
    "SeenPass",
    "SpplError",
    "StudentT",
    "available_likelihoods",
    "check_proposals",
    "bind_region",
    "compare_scenes",
    "compile_model",
    "find_scenes",
    "joint_check",
    "load_cameras",
    "load_model",
    "load_observations",
    "load_run",
    "open_posterior",
    "parse",
    "raycast",
    "register_likelihood",
    "render_observations",
    "run_chain",
    "run_chains",
    "run_dataset",
    "sample_noise",
    "sample_objects",
    "seen_reference",
    "verify_model",
    "write_observations",
    "write_posterior",
]
