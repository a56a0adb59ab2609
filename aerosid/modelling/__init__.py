"""Modelling: what each coefficient's linear model holds, and the modelling loop's history.

``models``       model specifications: which terms each channel's linear model holds (defaults)
``expressions``  a small, safe expression language for model terms
``model_specs``  model spec files relative to a parent model: ``add``, ``remove`` and ``terms``
``versions``     model versions of a run: every fit is kept, with its spec, metrics and parent
``loop``         one step of the modelling loop on a run folder (``aerosid diagnose``)
``effects``      the catalogue of aerodynamic effects the default linear models leave out
``aeromodel``    analytic aerodynamic model of a cruciform slender body (preflight or flight)
The diagnosis of what a model is missing is ``aerosid.diagnosis``.
"""
