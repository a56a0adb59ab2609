"""Identification: from flight signals to coefficients, and using an identified model.

``band``               the regression's common band: band-limited rates, accelerations and regressors
``identified``         the identified model of a run folder (coefficients and each channel's terms)
``output_prediction``  simulating the model driven by another manoeuvre's measured controls
``validate``           coefficient and output prediction of another manoeuvre, Theil's inequality coefficient
``validation_report``  the self-contained ``validation.html``
"""
