"""What `aerosid run` says at its end: the samples and Mach window the regression used,
and the diagnosis verdict with the spec lines to paste.  Reads the run folder only
(flight_data.parquet, diagnosis.json, run.json); returns text lines, prints nothing."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd


def _count(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def regression_window_line(run_dir: Path, mach_half_width: float | None) -> str | None:
    """'regressed 7 633 of 60 001 samples, Mach 11.90–12.90 (|M − 12.4| ≤ 0.5)', as identify() selects them."""
    from aerosid.identification.identify import mach_window_mask
    from aerosid.vehicles.vehicle import load_vehicle
    from aerosid.modelling.versions import run_vehicle

    path = run_dir / "flight_data.parquet"
    if not path.is_file():
        return None
    mach = pd.read_parquet(path, columns=["mach"])["mach"].to_numpy(float)
    veh = load_vehicle(run_vehicle(run_dir))
    mask = mach_window_mask(mach, veh.mach_reference, mach_half_width)
    used = mach[mask]
    rule = ("the whole flight" if mach_half_width is None else
            f"|M − {veh.mach_reference:g}| ≤ {mach_half_width:g}, --mach-half-width")
    span = f", Mach {np.nanmin(used):.2f}–{np.nanmax(used):.2f}" if used.size else ""
    return f"regressed {_count(int(mask.sum()))} of {_count(len(mach))} samples{span} ({rule})"


def first_sentence(text: str) -> str:
    """Up to the first '. ' followed by a capital letter: the verdict of a diagnosis message."""
    import re

    return re.split(r"(?<=\.)\s+(?=[A-Z])", text.strip(), maxsplit=1)[0]


def _vanes_late(run_dir: Path) -> bool:
    """Whether RUN_DIR/run.json records an airdata_delay finding."""
    try:
        findings = json.loads((run_dir / "run.json").read_text()).get("findings") or []
    except (OSError, json.JSONDecodeError, AttributeError):
        return False
    return any(isinstance(f, dict) and f.get("kind") == "airdata_delay" for f in findings)


def verdict_lines(run_dir: Path) -> list[str]:
    """The first line of diagnosis.json's message (the recommendation, or that nothing
    significant is missing) and, for a recommendation, the spec lines that add it."""
    from aerosid.modelling.model_specs import paste_lines

    path = run_dir / "diagnosis.json"
    if not path.is_file():
        return [f"diagnosis: none written (see {run_dir / 'ledger.jsonl'})"]
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        return [f"diagnosis: {path} cannot be read ({exc})"]
    message = str(doc.get("message") or "").strip()
    lines = [f"diagnosis: {first_sentence(message.splitlines()[0]) if message else '(no message)'}"]
    if _vanes_late(run_dir):  # a data fault before any model question (aerosid.identification.vanes)
        lines.append("first the air data: the run found its vanes late against the IMU (finding airdata_delay); "
                     "a late vane is what the fit makes up with terms that lead alpha (a 'lag' or 'lead' the "
                     "localisation names in CN or Cm may be it): set the finding's delay_s (or vane_position_m) "
                     "in the vehicle file and run again before adding terms")
    effects = doc.get("effects") or []
    name = doc.get("recommended")
    top = (next((e for e in effects if e.get("name") == name), None) if name else
           next((e for e in effects if e.get("significant")), None) if "recommended" not in doc else None)
    if top and top.get("spec_term"):
        lines += [f"to add it, put these lines in a model spec file SPEC and run `aerosid fit {run_dir} --model SPEC`:",
                  *("  " + li for li in paste_lines(top["channel"], top["spec_term"]).splitlines())]
    elif not name:  # nothing from the catalogue: the localisation's strongest significant term, if any
        found = sorted((f for fs in (doc.get("localisation") or {}).values() for f in fs if f.get("significant")),
                       key=lambda f: -abs(f.get("t_value") or 0.0))
        if found:
            f = found[0]
            main = (f.get("evidence") or {}).get("main_effect")
            terms = [f["spec_line"]] + ([f"{main} = {f['variable']}"] if main else [])
            lines += [f"outside the catalogue, the localisation's strongest term ({f['channel']}: {f['id']}); to add "
                      f"it, put these lines in a model spec file SPEC and run `aerosid fit {run_dir} --model SPEC`:",
                      *("  " + li for li in paste_lines(f["channel"], *terms).splitlines())]
    open_pair = next((c for c in doc.get("lookalikes") or [] if c.get("verdict") == "unresolved"
                      and len(c.get("alternatives") or []) > 1), None) if not name else None
    if open_pair:  # the manoeuvre that would separate them, and the command that designs it
        lines.append(f"to separate them: {open_pair.get('separating_manoeuvre', 'another manoeuvre')}; "
                     f"`aerosid design {run_dir} --effect {open_pair['alternatives'][0]['name']} --versus "
                     f"{open_pair['alternatives'][1]['name']} --out DIR` proposes "
                     "one; fly it and `aerosid run` this flight's and the new flight's telemetry together")
    # the simulated check: `history --against` simulates the longitudinal axis, and two specs that each
    # add one term compare them only when neither is in the model yet
    if open_pair and open_pair.get("channel", "Cm") in ("Cm", "CN") and open_pair.get("in_model") is None:
        a, b = (alt["name"] for alt in open_pair["alternatives"][:2])
        lines.append(f"or compare them simulated, before flying: spec files A and B with `add = [\"{a}\"]` and "
                     f"`add = [\"{b}\"]` under [{open_pair.get('channel', 'Cm')}]; `aerosid fit {run_dir} --model A`; "
                     f"`aerosid fit {run_dir} --model B --parent vP` (vP: A's parent, `aerosid history` lists it); "
                     f"`aerosid history {run_dir} --against TELEMETRY` (this flight's or another's): the term whose "
                     "simulated alpha follows the measured one better is the likelier")
    lines.append(f"details: `aerosid diagnose {run_dir}`, {run_dir / 'report.html'}")
    return lines


def _coefficients_table(run_dir: Path):
    """RUN_DIR/coefficients.parquet as a DataFrame, or None when it is missing or unreadable."""
    path = run_dir / "coefficients.parquet"
    if not path.is_file():
        return None
    import pandas as pd

    try:
        return pd.read_parquet(path)
    except (OSError, ValueError):
        return None


def undetermined_line(run_dir: Path) -> str | None:
    """The coefficients the flight does not determine (95 % interval holds 0), or None."""
    from aerosid.identification.term_report import undetermined

    table = _coefficients_table(run_dir)
    names = undetermined(table) if table is not None else []
    if not names:
        return None
    channel = (dict(zip(table["coefficient"].astype(str), table["channel"].astype(str)))
               if "channel" in table.columns else {})
    pitch = [n for n in names if channel.get(n) == "Cm"]
    advice = ("more excitation of their axis would determine them (a longer or larger input)"
              + (f"; for the pitch terms, `aerosid design {run_dir} --effect {pitch[0]} --out DIR` proposes one "
                 "(seed-rlv and the JSBSim aircraft)" if pitch else ""))
    return f"not determined by this flight (95 % interval holds 0, not even the sign is known): {', '.join(names)}; {advice}"


def wrong_sign_line(run_dir: Path) -> str | None:
    """The damping coefficients whose whole 95 % interval came out positive, or None."""
    from aerosid.identification.term_report import wrong_sign

    table = _coefficients_table(run_dir)
    names = wrong_sign(table) if table is not None else []
    if not names:
        return None
    return (f"came out positive at 95 %, a sign damping seldom has: {', '.join(names)}; usually the noise in the "
            "regressor (alpha-dot read off noisy angles, a noisy rate) or its collinearity, not physics; the warnings "
            "of its channel say how its interval and the others' include the model without it")


def run_outcome_lines(run_dir: Path, mach_half_width: float | None) -> list[str]:
    window = regression_window_line(run_dir, mach_half_width)
    weak = undetermined_line(run_dir)
    signed = wrong_sign_line(run_dir)
    return ([window] if window else []) + ([weak] if weak else []) + ([signed] if signed else []) + verdict_lines(run_dir)
