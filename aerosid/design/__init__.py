"""Experiment design (issue 20): the manoeuvre that would make an effect detectable, or
separate two confusable terms, within the vehicle's limits (``aerosid design``; docs/design.md)."""
from aerosid.design.core import Design, DesignError, design, write_design
from aerosid.design.predict import Prediction, ResidualModel, predict_covariance

__all__ = ["Design", "DesignError", "design", "write_design", "Prediction", "ResidualModel", "predict_covariance"]
