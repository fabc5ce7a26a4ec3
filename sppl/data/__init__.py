"""Observations: calibrated cameras and the RGB and depth images they took, read and written."""
