"""Scoring a scene hypothesis against the observations: the fast GL-side scorer and its numpy twin."""
