"""sppl: Bayesian scene understanding with a small stochastic scene language."""
__version__ = "0.1.0"
