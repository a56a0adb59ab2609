"""Identification: from flight signals to coefficients (the regression's inputs and checks)."""
