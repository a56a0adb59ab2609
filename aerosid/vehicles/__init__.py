"""Vehicles: what is known of the airframe before a flight, and the physics it flies in.

``vehicle``        the vehicle file (vehicle.toml): geometry, mass and inertia, sensors, preflight aero
``aerodb``         a vehicle's aerodynamic database (tables) and ``aerodb_build`` that writes it
``atmosphere``     air data: US Standard Atmosphere 1976 or measured density / pressures
``rigid_body``     rigid-body rotational dynamics shared by the simulator and the estimator
``accel``, ``keys``, ``units``   accelerometer lever arm, vehicle-file keys, unit conversion
Importers of real flight data (SIDPAC .mat, flight-test CSV) into aerosid's raw telemetry
contract, with the vehicle file beside it: ``importers``, ``sidpac``, ``csv_import``,
``vehicle_toml``.
"""
