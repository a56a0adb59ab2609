"""Using an identified model: predicting other manoeuvres with it (``aerosid validate``).

``identified``         the identified model of a run folder (coefficients and each channel's terms)
``output_prediction``  simulating the model driven by another manoeuvre's measured controls
``validate``           coefficient and output prediction of another manoeuvre, Theil's inequality coefficient
``validation_report``  the self-contained ``validation.html``
"""
