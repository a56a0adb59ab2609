"""Vehicles: what is known of the airframe before a flight, and the physics it flies in.

``vehicle``        the vehicle file (vehicle.toml): geometry, mass and inertia, sensors, preflight aero
``aerodb``         a vehicle's aerodynamic database (tables) and ``aerodb_build`` that writes it
``atmosphere``     air data: US Standard Atmosphere 1976 or measured density / pressures
``rigid_body``     rigid-body rotational dynamics shared by the simulator and the estimator
``keys``           the keys a vehicle file may hold, and the check of a parsed file against them
``accel``          where the accelerometer sits, from accelerations at the sensor and at the CG
``units``          unit conversion of imported flight data (pint)
Importers of real flight data (SIDPAC .mat, flight-test CSV) into aerosid's raw telemetry
contract, with the vehicle file beside it: ``importers``, ``sidpac``, ``csv_import``,
``vehicle_toml``.
"""
