"""Identification: from flight signals to coefficients, and using an identified model.

``flight_data``        from a smoothed segment to the flight data the regression reads
``flight_coefficients`` flight force and moment coefficients from smoothed states
``inversion``          angle of attack and sideslip from the preflight force database
``derivatives``        zero-phase low-pass of vanes, smoothing derivatives (alpha-dot, beta-dot)
``vanes``              the vanes against the IMU: their delay (estimated, reported) and position (moved to the CG)
``eiv``                errors in the regressors: SIMEX's numerics (the angles', rates' and controls' noise)
``eiv_fit``            the fits corrected by SIMEX, the regressors' noise the flight data declare, control-noise warnings
``prior_structure``    after the fit: the pitch-damping prior, model-structure uncertainty, wrong-sign damping
``regression``         linear least squares with the coloured-residual covariance (``fit_linear``)
``residual_covariance`` residual autocovariance, lag window, Morelli-Klein covariance
``linear_fit``         ``LinearFit``, the result of ``fit_linear``
``structure``          model structure determination (stepwise term selection)
``identify``           the regression stage: every channel's model fitted, the coefficients table
``coefficient_units``  per radian or per degree: a coefficient's unit from its term
``crb``                Cramer-Rao bounds of a run's coefficients
``term_report``        the fitted terms of a model version as text
``band``               the regression's common band: band-limited rates, accelerations and regressors
``identified``         the identified model of a run folder (coefficients and each channel's terms)
``output_prediction``  simulating the model driven by another manoeuvre's measured controls
``validate``           coefficient and output prediction of another manoeuvre, Theil's inequality coefficient
``validation_report``  the self-contained ``validation.html``
``output_error``       output-error fit of a model (Gauss-Newton on simulated outputs)
``refine``             ``aerosid refine``: output error started from a run's equation-error estimates
"""
