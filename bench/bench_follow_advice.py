"""Issue 18/20 bench: follow the diagnosis' advice end to end, as an engineer would, with the CLI.

For each (hidden effect, seed) the chain is run through the `aerosid` command line (subprocesses,
the same commands a user types; nothing is called behind the CLI's back):

1. ``aerosid simulate --case seed-rlv --effect E --seed S --out W/std`` and
   ``aerosid run W/std/telemetry.parquet --out W/std_run``: the standard flight and its diagnosis
   (``aerosid run`` ends with the diagnosis of the default models, RUN/diagnosis.json);
2. ``aerosid design W/std_run --effect E [--versus V] --out W/des_<variant>``, on *that seed's* run,
   for two variants: ``plain`` (``--effect E``: the catalogue size, as in the README example) and
   ``versus`` (``--effect E --versus V``: separate the look-alikes); for control_alpha also ``top``
   (``--effect`` the first of the standard diagnosis' unresolved look-alikes: what a user who only
   reads the diagnosis would design for -- alpha_nonlinearity on control_alpha's seed 1);
3. ``aerosid simulate --case seed-rlv --effect E --input W/des_<variant>/input.parquet --seed 100+S``
   (same hidden effect, another noise seed) and ``aerosid run`` on it: the designed flight alone;
4. ``aerosid run W/std/telemetry.parquet W/fly_<variant>/telemetry.parquet --out W/pooled_<variant>``:
   both manoeuvres pooled into one identification (issue 11's pooled run), diagnosed.

From each diagnosis.json: ``recommended``, the look-alike verdict, ``loop_closed``, the top candidate,
and the target term's estimate +- sigma (the diagnosis' fit of base + term, coloured-residual sigma)
against the truth in the flight's truth.json.  E = ``none`` flies the same designs (designed on the
no-effect run with ``--effect alpha_nonlinearity``) without a hidden effect: any recommendation there
is false.

    python bench/bench_follow_advice.py --jobs 2 [--seeds 0-9] [--none-seeds 0-4] [--work DIR]
    -> bench/results/follow_advice.md, bench/results/follow_advice_runs.csv

Every step's output folder is kept in --work and reused when present (delete it to redo).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import date
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
LOOKALIKE = {"alpha_nonlinearity": "control_alpha", "control_alpha": "alpha_nonlinearity"}
COEF = {"alpha_nonlinearity": "Cm_alpha_abs_alpha", "control_alpha": "Cm_alpha_delta_p"}
NOTES = "<!-- written by hand from the tables above; kept when the bench rewrites them -->"
DESIGN_SEED_OFFSET = 100
"""The designed flight's noise seed: 100 + the standard flight's seed."""


def _aerosid() -> list[str]:
    exe = Path(sys.executable).parent / "aerosid"
    return [str(exe)] if exe.is_file() else [sys.executable, "-c", "from aerosid.cli import main; main()"]


def _cli(args: list[str], log: Path, done: Path | None = None) -> float:
    """Run one aerosid command (skipped when `done` exists); its output goes to `log`. Seconds taken."""
    if done is not None and done.exists():
        return 0.0
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    with open(log, "a") as fh:
        fh.write(f"$ aerosid {' '.join(args)}\n")
        fh.flush()
        rc = subprocess.run(_aerosid() + args, stdout=fh, stderr=subprocess.STDOUT, env=env).returncode
    if rc != 0:
        raise RuntimeError(f"aerosid {' '.join(args)} failed (exit {rc}); see {log}")
    return time.perf_counter() - t0


def _read_diag(run_dir: Path, target: str | None, truth_json: Path) -> dict:
    d = json.loads((run_dir / "diagnosis.json").read_text())
    look = next((c for c in d.get("lookalikes", []) if not any(a.get("in_model") for a in c["alternatives"])), None)
    top = d["effects"][0] if d["effects"] else {}
    sig = [e["name"] for e in d["effects"] if e.get("significant")]
    row = {"recommended": d.get("recommended") or "", "loop_closed": bool(d.get("loop_closed")),
           "top": top.get("name", ""), "top_significant": bool(top.get("significant")),
           "significant": " ".join(sig),
           "verdict": look["verdict"] if look else "",
           "lookalike_names": " ".join(a["name"] for a in look["alternatives"]) if look else "",
           "delta_max": max(look["delta"].values()) if look and look.get("delta") else float("nan"),
           "message": d.get("message", "")[:300]}
    if target:
        e = next((x for x in d["effects"] if x["name"] == target), None)
        truth = json.loads(truth_json.read_text())["coefficients"].get(COEF[target], float("nan"))
        row.update(truth=truth, rank=(d["effects"].index(e) + 1) if e else -1,
                   target_significant=bool(e and e.get("significant")),
                   estimate=e["estimate"] if e else float("nan"), sigma=e["std_error"] if e else float("nan"),
                   estimate_simex=e.get("estimate_simex", float("nan")) if e else float("nan"),
                   p_value=e["p_value"] if e else float("nan"))
    return row


def chain(job: tuple) -> list[dict]:
    """One (effect, seed): the standard flight, then each design variant flown, alone and pooled."""
    effect, seed, variants, work = job
    w = Path(work) / f"{effect}_{seed}"
    w.mkdir(parents=True, exist_ok=True)
    log = w / "log.txt"
    eff = [] if effect == "none" else ["--effect", effect]
    target = None if effect == "none" else effect
    design_effect = "alpha_nonlinearity" if effect == "none" else effect
    t = {}
    t["sim_std"] = _cli(["simulate", "--case", "seed-rlv", *eff, "--seed", str(seed), "--out", str(w / "std")],
                        log, w / "std" / "truth.json")
    t["run_std"] = _cli(["run", str(w / "std" / "telemetry.parquet"), "--out", str(w / "std_run")], log,
                        w / "std_run" / "diagnosis.json")
    base = {"effect": effect, "seed": seed}
    rows = [{**base, "variant": "", "flight": "standard", **_read_diag(w / "std_run", target, w / "std" / "truth.json"),
             "seconds": t["sim_std"] + t["run_std"]}]
    for variant in variants:
        des, fly, fly_run, pooled = (w / f"des_{variant}", w / f"fly_{variant}", w / f"fly_{variant}_run",
                                     w / f"pooled_{variant}")
        top = rows[0]["lookalike_names"].split()[0] if rows[0]["verdict"] == "unresolved" else design_effect
        dargs = ["design", str(w / "std_run"), "--effect", top if variant == "top" else design_effect,
                 "--out", str(des), "--quiet"]
        if variant == "versus":
            dargs[4:4] = ["--versus", LOOKALIKE[design_effect]]
        t_des = _cli(dargs, log, des / "design.json")
        dj = json.loads((des / "design.json").read_text())
        man = dj["manoeuvre"]
        design_info = {"design": man["label"], "amplitude_rad": man["amplitude_rad"],
                       "design_verdict": dj["verdict"].split(":")[0],
                       "design_sizes": " ".join(f"{s:.3g}" for s in dj["sizes"]),
                       "design_sigma_after": dj["after"][dj["targets"][0]]["sigma"]}
        t_fly = _cli(["simulate", "--case", "seed-rlv", *eff, "--input", str(des / "input.parquet"),
                      "--seed", str(DESIGN_SEED_OFFSET + seed), "--out", str(fly)], log, fly / "truth.json")
        t_fr = _cli(["run", str(fly / "telemetry.parquet"), "--out", str(fly_run)], log, fly_run / "diagnosis.json")
        t_po = _cli(["run", str(w / "std" / "telemetry.parquet"), str(fly / "telemetry.parquet"), "--out",
                     str(pooled)], log, pooled / "diagnosis.json")
        rows.append({**base, "variant": variant, "flight": "designed", **design_info,
                     **_read_diag(fly_run, target, fly / "truth.json"), "seconds": t_des + t_fly + t_fr})
        rows.append({**base, "variant": variant, "flight": "pooled", **design_info,
                     **_read_diag(pooled, target, fly / "truth.json"), "seconds": t_po})
    (w / "rows.json").write_text(json.dumps(rows, indent=1, default=float))
    return rows


def _est(r) -> str:
    return "-" if pd.isna(r.get("estimate")) else f"{r['estimate']:+.3f} ± {r['sigma']:.3f}"


def _what(r) -> str:
    """recommended, else the verdict in a word."""
    if r["recommended"]:
        return f"**{r['recommended']}**"
    if r["verdict"] == "unresolved":
        return f"none (unresolved: {r['lookalike_names'].replace(' ', ' / ')})"
    return "none (loop closed)" if r["loop_closed"] else "none"


def _counts(g: pd.DataFrame, target: str | None) -> str:
    n = len(g)
    rec = g["recommended"]
    if target is None:
        return f"{int((rec != '').sum())}/{n}"
    return (f"{int((rec == target).sum())}/{n} | {int(((rec != '') & (rec != target)).sum())}/{n} | "
            f"{int((rec == '').sum())}/{n}")


def report(df: pd.DataFrame, wall_s: float, args) -> str:
    from machine import cpu_model, loadavg

    L = ["# Following the diagnosis' advice end to end (issues 18 and 20)", "",
         f"{date.today()}, {cpu_model()}, {os.cpu_count()} cores shared with other jobs, load {loadavg()}; the CLI steps "
         f"took {df['seconds'].sum() / 60:.0f} min in all (2 chains at a time). "
         f"`python bench/bench_follow_advice.py --jobs 2 --seeds {args.seeds} --ca-seeds {args.ca_seeds} "
         f"--ca-variants {args.ca_variants} --none-seeds {args.none_seeds} --none-variants "
         f"{args.none_variants or args.variants}`" + (" (tables rebuilt from the step folders with --report-only)"
                                                      if args.report_only else "")
         + ". Per-flight rows: `bench/results/follow_advice_runs.csv`.", ""]
    an = df[df["effect"] == "alpha_nonlinearity"]
    variants = [v for v in df["variant"].unique() if v]
    kinds = [("", "standard")] + [(v, f) for v in variants for f in ("designed", "pooled")]

    def label(v, f):
        return "standard flight" if f == "standard" else f"{f} ({v} design)"

    if len(an):
        L += ["## alpha_nonlinearity hidden (truth Cm_alpha_abs_alpha = -0.43)", "",
              "*verdicts*: the look-alike comparison of the top candidate (*no comparison*: no confusable "
              "candidate, the top one is judged alone). *estimate*: the diagnosis' fit of base + alpha|alpha| "
              "(coloured-residual sigma); *SIMEX*: its errors-in-variables corrected estimate (`estimate_simex`).", "",
              "| flight | recommended alpha_nonlinearity | recommended another | none | verdicts | target significant "
              "| target first & significant | estimate: mean, sd over seeds | mean sigma | estimate within 2 sigma of truth "
              "| SIMEX estimate: mean |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
        for v, f in kinds:
            g = an[(an["variant"] == v) & (an["flight"] == f)]
            if not len(g):
                continue
            verd = ", ".join(f"{k} {c}" for k, c in g["verdict"].replace("", "no comparison").value_counts().items())
            within = int(((g["estimate"] - g["truth"]).abs() <= 2 * g["sigma"]).sum())
            L.append(f"| {label(v, f)} | {_counts(g, 'alpha_nonlinearity')} | {verd} "
                     f"| {int(g['target_significant'].sum())}/{len(g)} "
                     f"| {int(((g['rank'] == 1) & g['target_significant']).sum())}/{len(g)} "
                     f"| {g['estimate'].mean():+.3f}, {g['estimate'].std():.3f} | {g['sigma'].mean():.3f} "
                     f"| {within}/{len(g)} | {g['estimate_simex'].mean():+.3f} |")
        L += ["", "### Per seed", "",
              "| seed | standard flight | design (variant: manoeuvre, design verdict) | designed flight alone | est ± sigma "
              "| both flights pooled | est ± sigma | standard est ± sigma |", "|---|---|---|---|---|---|---|---|"]
        for s, g in an.groupby("seed"):
            std = g[g["flight"] == "standard"].iloc[0]
            for v in variants:
                d = g[(g["variant"] == v) & (g["flight"] == "designed")]
                p = g[(g["variant"] == v) & (g["flight"] == "pooled")]
                if not len(d):
                    continue
                d, p = d.iloc[0], p.iloc[0]
                L.append(f"| {s} | {_what(std)} | {v}: {d['design']}, {d['amplitude_rad']:.3f} rad; "
                         f"{d['design_verdict']} | {_what(d)} | {_est(d)} | {_what(p)} | {_est(p)} | {_est(std)} |")
    ca = df[df["effect"] == "control_alpha"]
    if len(ca):
        L += ["", "## control_alpha hidden (truth Cm_alpha_delta_p from truth.json)", "",
              "| seed | flight | recommended | verdict, Delta max | control_alpha est ± sigma | truth | design |",
              "|---|---|---|---|---|---|---|"]
        for _, r in ca.iterrows():
            L.append(f"| {r['seed']} | {label(r['variant'], r['flight'])} | {_what(r)} | {r['verdict'] or '-'}, "
                     f"{r['delta_max']:.1f} | {_est(r)} | {r['truth']:+.4f} | "
                     f"{'' if pd.isna(r.get('design')) else r['design'] + ', ' + r['design_verdict']} |")
    no = df[df["effect"] == "none"]
    if len(no):
        L += ["", "## No hidden effect, flown through the same kind of design (false recommendations)", "",
              "| flight | something recommended | what | verdicts | top candidate significant |", "|---|---|---|---|---|"]
        for v, f in kinds:
            g = no[(no["variant"] == v) & (no["flight"] == f)]
            if not len(g):
                continue
            what = ", ".join(f"{k} {c}" for k, c in g.loc[g["recommended"] != "", "recommended"].value_counts().items())
            verd = ", ".join(f"{k} {c}" for k, c in g["verdict"].replace("", "no comparison").value_counts().items())
            L.append(f"| {label(v, f)} | {_counts(g, None)} | {what or '-'} | {verd} | "
                     f"{int(g['top_significant'].sum())}/{len(g)} |")
    return "\n".join(L) + "\n"


def _seeds(text: str) -> list[int]:
    out = []
    for part in filter(None, text.split(",")):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-9", help="alpha_nonlinearity seeds")
    ap.add_argument("--ca-seeds", default="1", help="control_alpha seeds (1: its unresolved one)")
    ap.add_argument("--none-seeds", default="0-4", help="no-effect seeds")
    ap.add_argument("--variants", default="plain,versus")
    ap.add_argument("--ca-variants", default="plain,versus,top",
                    help="control_alpha's variants; top = --effect the first of the unresolved look-alikes")
    ap.add_argument("--none-variants", default=None, help="design variants flown without an effect (default: --variants)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--work", default="/tmp/aerosid_follow_advice")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--report-only", action="store_true", help="rebuild the report from --work's rows")
    args = ap.parse_args()
    variants = tuple(v for v in args.variants.split(",") if v)
    none_variants = tuple(v for v in (args.none_variants or args.variants).split(",") if v)
    jobs = ([("alpha_nonlinearity", s, variants, args.work) for s in _seeds(args.seeds)]
            + [("control_alpha", s, tuple(args.ca_variants.split(",")), args.work) for s in _seeds(args.ca_seeds)]
            + [("none", s, none_variants, args.work) for s in _seeds(args.none_seeds)])
    t0 = time.perf_counter()
    rows: list[dict] = []
    if args.report_only:
        for e, s, _, w in jobs:
            f = Path(w) / f"{e}_{s}" / "rows.json"
            if f.is_file():
                rows += json.loads(f.read_text())
    else:
        with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as ex:
            for i, r in enumerate(ex.map(chain, jobs)):
                rows += r
                print(f"[{i + 1}/{len(jobs)}] {r[0]['effect']} seed {r[0]['seed']}: standard -> "
                      f"{r[0]['recommended'] or 'none'}; "
                      + "; ".join(f"{x['variant']} {x['flight']} -> {x['recommended'] or 'none'}" for x in r[1:]),
                      flush=True)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    df.to_csv(out / "follow_advice_runs.csv", index=False, float_format="%.6g")
    md = out / "follow_advice.md"
    notes = md.read_text().split(NOTES, 1)[1] if md.is_file() and NOTES in md.read_text() else "\n"
    md.write_text(report(df, time.perf_counter() - t0, args) + "\n" + NOTES + notes)
    print(f"wrote {out / 'follow_advice.md'} and {out / 'follow_advice_runs.csv'}")


if __name__ == "__main__":
    main()
