"""The model versions (a tree) and the audit trail."""
from __future__ import annotations

import numpy as np

from aerosid.report.html import CHANNELS, _H, _e, _finite, _num, _note, _p, _table
from aerosid.report.plots import _figure, _svg
from aerosid.report.rundir import Shown, _Run


# --------------------------------------------------------------------------- versions and audit
def tree_order(versions) -> list[tuple[object, int]]:
    """(version, depth) in depth-first order from the roots: each child under its parent,
    siblings in creation order.  A version whose parent is missing is a root."""
    ids = {v.id for v in versions}
    children: dict = {}
    roots = []
    for v in versions:
        if v.parent and v.parent in ids:
            children.setdefault(v.parent, []).append(v)
        else:
            roots.append(v)
    out: list = []

    def walk(v, depth):
        out.append((v, depth))
        for c in children.get(v.id, []):
            walk(c, depth + 1)

    for r in roots:
        walk(r, 0)
    return out


def tree_edges(versions) -> list[tuple[object, object]]:
    """(parent, child) for every version whose parent is stored: the lines of the version plot."""
    by_id = {v.id: v for v in versions}
    return [(by_id[v.parent], v) for v in versions if v.parent and v.parent in by_id]


def _s_versions(run: _Run, shown: Shown) -> str:
    h = shown.history
    if shown.problem:
        return _note(shown.problem)
    if h is None or not h.versions:
        return _note("No model versions yet. `aerosid fit RUN_DIR --model SPEC` stores v001 (the default models) "
                     "and each new model as the next version.")
    tab = h.table().set_index("version")
    chans = [c for c in CHANNELS if f"rms_{c}" in tab] + [c[4:] for c in tab.columns if c.startswith("rms_")
                                                          and c[4:] not in CHANNELS]
    rows = []
    for v, depth in tree_order(h.versions):
        r = tab.loc[v.id]
        mark = " ◀ shown" if v.id == shown.version else ""
        name = _H(("&nbsp;&nbsp;&nbsp;" * max(depth - 1, 0) + ("└─ " if depth else "")) + _e(v.id)
                  + (f"<b>{_e(mark)}</b>" if mark else ""))
        rows.append([name, r["parent"] or "—", r["changes"], r["note"], *(r[f"rms_{c}"] for c in chans)])
    ids = shown.identities
    out = [_p("Every fit is kept as an immutable version with its parent, drawn as a tree (each version under the "
              "one it was derived from). Changes are relative to the parent; the numbers are the residual RMS per "
              "channel (lower is better)."
              + (f" {', '.join(ids)}: identities by construction, their RMS is numerical (not plotted)." if ids else "")),
           _table(["version", "parent", "changes", "note", *(f"RMS {c}" + (" (identity)" if c in ids else "")
                                                            for c in chans)], rows, id="versions-table")]
    fig, (ax, rel) = _figure((9, 3.2), ncols=2)
    by_id = {v.id: v for v in h.versions}
    first = h.versions[0]
    for j, ch in enumerate(chans):
        if ch in ids:
            continue
        colour = f"C{j % 10}"
        ref = first.channel_metric(ch, "rms_residual")
        for axis, scale in ((ax, None), (rel, ref)):
            def y(v):
                val = v.channel_metric(ch, "rms_residual")
                if not (_finite(val) and val > 0):
                    return np.nan
                return val if scale is None else (100 * val / scale if _finite(scale) and scale > 0 else np.nan)

            xs = [v.number for v in h.versions]
            axis.plot(xs, [y(v) for v in h.versions], "o", color=colour, ms=4, label=ch)
            for p, v in tree_edges(h.versions):  # parent -> child only: siblings are not joined
                axis.plot([p.number, v.number], [y(p), y(v)], "-", color=colour, lw=1.0)
    ax.set_yscale("log")
    ax.set_ylabel("residual RMS")
    rel.set_ylabel(f"% of {first.id}")
    rel.axhline(100, color="0.4", lw=0.6)
    for a in (ax, rel):
        a.set_xlabel("model version (lines join each version to its parent)")
        a.set_xticks(sorted({v.number for v in h.versions}))
        if shown.version in by_id:
            a.axvline(by_id[shown.version].number, color="0.5", lw=0.6, ls=":")
    rel.legend(fontsize=8, loc="best")
    out.append(_svg(fig, "versions", "Residual RMS per channel against model version, as a tree (each line joins a "
                                     "version to its parent): absolute (log scale, left) and relative to the first "
                                     "version (right)"))
    return "\n".join(out)


def _s_audit(run: _Run) -> str:
    if not run.ledger:
        return _note("No ledger.jsonl in this run folder.")
    latest: dict = {}
    for rec in run.ledger:
        if rec.get("stage") in (None, "inbox"):
            continue
        latest[(rec.get("stage"), rec.get("segment") or "")] = rec
    rows = [(rec.get("time_utc", ""), stage, seg or "—", rec.get("status", ""), _num(rec.get("duration_s"), ".2f"),
             rec.get("rows_in"), rec.get("rows_out"), rec.get("flagged_rows"),
             ", ".join(str(o.get("sha256", ""))[:12] for o in rec.get("outputs") or []) or "—",
             rec.get("error") or "") for (stage, seg), rec in latest.items()]
    return (_p(f"The latest ledger record of each stage ({len(run.ledger)} records in ledger.jsonl). "
               "`aerosid audit FILE` traces any output back to the raw telemetry.")
            + _table(["time (UTC)", "stage", "segment", "status", "duration [s]", "rows in", "rows out", "flagged",
                      "output SHA-256 (first 12)", "error"], rows, id="audit-table", cls="compact"))


