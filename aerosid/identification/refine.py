"""Refine a run's model by output error on a manoeuvre (``aerosid refine``).

The manoeuvre goes through the run's own estimation (as ``aerosid validate`` does:
:func:`aerosid.identification.validate.estimate_manoeuvre`); the model's axes are then fitted
by output error (:mod:`aerosid.identification.output_error`), started from the run's
equation-error estimates, driven by the measured controls (before the band's low-pass),
airspeed, dynamic pressure and attitude (telemetry columns ``phi_rad``, ``theta_rad``), and
compared with the measured alpha, q, a_z (beta, p, r, a_y).  Usually the manoeuvre the run
was identified on; any other of the same vehicle works too.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from aerosid.identification.identified import IdentifiedModel, load_identified_model, with_preflight_identities
from aerosid.identification.output_error import axis_coefficients, free_coefficients, output_error_fit
from aerosid.identification.output_prediction import prediction_inputs
from aerosid.identification.validate import attitude_on, choose_axes, estimate_manoeuvre, measured_outputs

__all__ = ["RefineResult", "refine", "write_refinement"]


@dataclass(frozen=True)
class RefineResult:
    """The output-error fits (OutputErrorFit per axis) of one run's model on one manoeuvre."""

    run_dir: str
    telemetry: str
    model: IdentifiedModel = field(repr=False)
    vehicle: str
    fits: tuple
    sources: dict = field(default_factory=dict)  # output -> where it was measured
    notes: tuple = ()

    def summary(self) -> str:
        lines = [f"output-error refinement of {self.model.source} on {self.telemetry} (vehicle {self.vehicle})",
                 "  started from the equation-error estimates; sigma: Morelli-Klein (coloured residuals), "
                 "sigma CRB: the Cramer-Rao bound with the fitted output noise"]
        lines += [f"  {o}: {s}" for o, s in self.sources.items()]
        for fit in self.fits:
            lines += ["", fit.summary()]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {"run_dir": self.run_dir, "telemetry": self.telemetry, "model": self.model.source,
                "vehicle": self.vehicle, "axes": {f.axis: f.to_dict() for f in self.fits},
                "sources": dict(self.sources), "notes": list(self.notes)}


def refine(run_dir: str | Path, telemetry: str | Path, *, vehicle: str | None = None, version: str | None = None,
           axes: str = "auto", free=None, windows=None, progress=None) -> RefineResult:
    """Output-error fits of RUN_DIR's model (the latest version, or `version`) on the manoeuvre
    in `telemetry`.  axes: lon, lat, both, or auto = lon, plus lat when the lateral channels
    are all identified (an identity channel, C_Y with beta inverted from it, is simulated at the
    preflight database's values and not refined: ``--axes lat`` asks for it); an axis whose fit
    fails under auto or both is a note, the other's result is kept.  free: the coefficients to
    refine (default: every identified one of each axis); windows: time windows [s] of the
    telemetry."""
    from aerosid.vehicles.vehicle import load_vehicle

    model = load_identified_model(run_dir, version)
    veh = load_vehicle(vehicle or model.vehicle)
    # auto: lat only when its channels were identified (a lateral refinement costs minutes); then the
    # identity channels (inverted angles) are simulated at the preflight database's values, not refined
    chosen, notes = choose_axes(model, axes)
    model, pre = with_preflight_identities(model, veh)
    notes = pre + notes
    if not chosen:
        raise ValueError("no axis to refine: " + "; ".join(notes))
    wanted = list(dict.fromkeys(free)) if free else None
    if wanted:  # a name in no channel of the model is a typo: refused before the estimation's minutes
        every = {t.coefficient for m in model.models.values() for t in m.terms}
        typo = [n for n in wanted if n not in every]
        if typo:
            raise ValueError(f"coefficient(s) {typo} are not in the model ({model.source}); its coefficients: "
                             f"{sorted(every)}")
        outside = [n for n in wanted if not any(n in axis_coefficients(model, ax) for ax in chosen)]
        if len(outside) == len(wanted):
            raise ValueError(f"none of {wanted} is a coefficient of the {'/'.join(chosen)} axis models: "
                             "nothing to refine (choose --axes)")
        if outside:
            notes.append(f"not refined (not in the {'/'.join(chosen)} axis models): {outside}")
    plan = {}  # axis -> its coefficients to refine, checked before the estimation
    for ax in chosen:
        names = [n for n in wanted if n in axis_coefficients(model, ax)] if wanted else None
        if wanted and not names:
            notes.append(f"{ax} axis not refined: none of {wanted} is one of its coefficients")
            continue
        plan[ax] = free_coefficients(model, ax, names)
    raw, est, fd, span, more = estimate_manoeuvre(run_dir, telemetry, model, veh, windows, "required", progress)
    notes += more
    att = attitude_on(raw, fd["t_s"].to_numpy(float), str(telemetry))
    inputs = prediction_inputs(fd, veh, att[0], att[1], span, wideband_controls=True)
    meas, sources = measured_outputs(est.preprocessed.frame, fd, veh, wideband=True)
    fits = []
    for k, (ax, names) in enumerate(plan.items()):
        if progress is not None:
            progress(f"output error ({ax})", k / len(plan))
        try:
            fits.append(output_error_fit(model, inputs, meas, veh, ax, free=names))
        except ValueError as exc:
            if axes in ("lon", "lat"):  # the one axis asked for by name fails the command
                raise
            notes.append(f"{ax} axis not refined: {exc}")  # the other axis's result is kept
    if not fits:
        raise ValueError("no axis refined: " + "; ".join(notes))
    if progress is not None:
        progress("done", 1.0)
    used = {o for f in fits for o in f.noise_std}
    return RefineResult(str(run_dir), str(telemetry), model, veh.name, tuple(fits),
                        {o: s for o, s in sources.items() if o in used}, tuple(notes))


def refined_table(result: RefineResult) -> pd.DataFrame:
    """coefficients.parquet rows (schemas/coefficients.py) of the refined model: the model's
    own table (the run's or the version's coefficients.parquet) with the output-error
    estimates in place of the refined rows' (std_error: sigma; std_error_ols and crb_std: the
    Cramer-Rao bound; the 95 % interval and t, p from sigma); ``method`` says which rows were
    refined.  ``aerosid validate --coefficients`` reads it."""
    from scipy.stats import norm

    if not result.model.path:
        raise ValueError("the refined model's own coefficients table is unknown (a model built in memory): "
                         "refine a run folder's model")
    table = pd.read_parquet(result.model.path)
    table["method"] = "equation error (not refined)"
    for f in result.fits:
        for k in f.names:
            est, s = f.estimate[k], f.sigma[k]
            row = table["coefficient"] == k
            table.loc[row, ["estimate", "std_error", "std_error_ols", "ci_low", "ci_high"]] = \
                [est, s, f.sigma_white[k], est - 1.96 * s, est + 1.96 * s]
            table.loc[row, "method"] = "output error" if f.converged else "output error (not converged)"
            if "crb_std" in table:
                table.loc[row, "crb_std"] = f.sigma_white[k]
            if "t_value" in table and s > 0:
                table.loc[row, ["t_value", "p_value"]] = [est / s, float(2 * norm.sf(abs(est / s)))]
    return table


def write_refinement(result: RefineResult, out_dir: str | Path) -> dict[str, Path]:
    """coefficients.parquet (:func:`refined_table`, checked against schemas/coefficients.py before
    it is written; its metadata hold the model's Mach window) and output_error.json (estimates,
    sigma, covariance, output noise and TIC per axis), each atomically."""
    from aerosid.io import write_json_atomic, write_parquet_atomic
    from schemas.coefficients import Coefficients

    import pandera.errors

    out = Path(out_dir)
    try:
        table = Coefficients.validate(refined_table(result), lazy=True)
    except pandera.errors.SchemaErrors as exc:
        raise ValueError(f"the refined coefficients fail schemas/coefficients.py: {exc.failure_cases}") from exc
    mhw = result.model.mach_half_width
    # the table first: the JSON that describes it only once it is there
    paths = {"coefficients": write_parquet_atomic(
        table, out / "coefficients.parquet",
        metadata={"aerosid.kind": "coefficients", "aerosid.mach_half_width": "none" if mhw is None else str(mhw),
                  "aerosid.model": f"{result.model.source} refined by output error on {result.telemetry}"})}
    paths["json"] = write_json_atomic(result.to_json(), out / "output_error.json")
    return paths
