"""Vehicles from users' data: importers of real flight data (SIDPAC .mat, flight-test CSV)
into aerosid's raw telemetry contract, with the vehicle file beside it."""
