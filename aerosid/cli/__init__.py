"""The ``aerosid`` command line: parses arguments and prints; the work happens in the core
(``aerosid.*``) or, for ``run``, in the Prefect flows (imported lazily so the core never
loads Prefect).

``app``            the command group ``main`` (the console script ``aerosid = aerosid.cli:main``)
``simulate``       ``aerosid simulate`` (a flight with known truth)
``run``            ``aerosid run`` and its pre-flight checks of the inputs
``audit``          ``aerosid audit`` (a file's lineage through the ledger)
``modelling``      ``aerosid diagnose`` / ``fit`` / ``history`` (the modelling loop)
``import_``        ``aerosid import sidpac|csv`` (``import`` is a Python keyword)
``validate``       ``aerosid validate`` (predict another manoeuvre)
``refine``         ``aerosid refine`` (output-error refinement of a run's model)
``design``         ``aerosid design`` (experiment design)
``prefect_server`` the Prefect API server ``aerosid run`` starts or reuses
``progress``       the progress display (rich)
``run_summary``    the summary ``aerosid run`` prints at the end
"""
from aerosid.cli.app import main

__all__ = ["main"]
