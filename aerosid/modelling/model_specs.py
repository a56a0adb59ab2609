"""Model spec files relative to a parent model: ``add``, ``remove`` and ``terms``.

A spec file has one table per channel (contracts.md "Model specs")::

    [Cm]
    add = ["control_alpha", "Cm_a3 = alpha**3"]   # the parent's terms stay
    remove = ["Cm_alpha_abs_alpha"]                # by coefficient, effect name or term text

    [Cl]
    terms = ["Cl_0 = 1", "Cl_alpha_r = alpha_r"]   # replaces the channel's model

``add`` and ``remove`` act on the parent model (the latest version, a chosen one, or
the defaults); ``terms`` replaces it, and :class:`SpecResult` says which of the
parent's terms a replacement dropped, so that writing ``terms = ["mach_cm_alpha"]``
for "add mach_cm_alpha" cannot pass unnoticed.  A term is ``NAME = EXPRESSION`` or
the name of any candidate the diagnosis can report (catalogue effects and the extra
candidates of :mod:`aerosid.diagnosis.candidates`, e.g. ``mach_cm0``, ``roll_damping``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from aerosid.modelling.models import (CHANNELS, MAX_SPEC_BYTES, MAX_TERMS, ChannelModel, ModelSpecError, Term, default_models,
                            parse_terms)

#: The keys a channel table may have.
KEYS = ("terms", "add", "remove")


def term_label(t: Term) -> str:
    return t.effect or f"{t.coefficient} = {t.expression}"


def paste_lines(channel: str, *terms: str) -> str:
    """The spec lines that add terms to a channel, ready to paste into a spec file."""
    quoted = ", ".join('"' + t.replace("\\", "\\\\").replace('"', '\\"') + '"' for t in terms)
    return f'[{channel}]\nadd = [{quoted}]'


@dataclass(frozen=True)
class ChannelChange:
    """What a spec did to one channel's model, relative to its parent."""

    channel: str
    replaced: bool  # a `terms = [...]` list replaced the channel's model
    added: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()
    dropped: tuple[str, ...] = ()  # the parent's coefficients a `terms` replacement left out
    already: tuple[str, ...] = ()  # `add` items the parent already had (no change)

    def warnings(self) -> list[str]:
        out = []
        if self.dropped:
            out.append(f"warning: [{self.channel}] terms = [...] replaces the parent's model and drops "
                       f"{', '.join(self.dropped)}; to keep them and only add terms, write add = [...] instead "
                       f"of terms = [...]")
        if self.already:
            out.append(f"note: [{self.channel}] add: {', '.join(self.already)} already in the parent's model "
                       "(nothing added)")
        return out


@dataclass(frozen=True)
class SpecResult:
    """The models a spec file gives (channels it does not mention keep the parent's) and
    what it changed per channel."""

    models: dict
    changes: tuple[ChannelChange, ...]
    source: str

    def warnings(self) -> list[str]:
        return [w for c in self.changes for w in c.warnings()]

    def summary(self) -> str:
        lines = [f"model spec {self.source}:"]
        for c in self.changes:
            bits = ([f"+{a}" for a in c.added] + [f"-{r}" for r in c.removed] + [f"-{d} (dropped)" for d in c.dropped])
            how = "terms replaced" if c.replaced else "relative to the parent"
            lines.append(f"  [{c.channel}] {how}: {', '.join(bits) or 'no change'}")
        return "\n".join(lines + [f"  {w}" for w in self.warnings()])


def _items(table: dict, key: str, channel: str, src: str) -> list[str] | None:
    if key not in table:
        return None
    value = table[key]
    if not isinstance(value, list) or not all(isinstance(t, str) for t in value):
        raise ModelSpecError(f"{src}: [{channel}] needs {key} = [\"NAME = EXPRESSION\", \"control_alpha\", ...] "
                             f"(a list of strings), not {type(value).__name__} {value!r:.60}")
    return value


def _matches(term: Term, item: str, named: Term | None) -> bool:
    """remove = [item]: a coefficient name, a candidate name (named: the term it stands for;
    a version read back from disk keeps only the expression of a non-catalogue candidate)
    or the term text."""
    item = item.strip()
    if item in (term.coefficient, term.effect) or (named is not None and named.coefficient == term.coefficient):
        return True
    name, eq, expr = item.partition("=")
    return bool(eq) and name.strip() == term.coefficient and expr.replace(" ", "") == term.expression.replace(" ", "")


def _named(item: str, channel: str, mach_reference: float) -> Term | None:
    if "=" in item:
        return None
    try:
        return parse_terms([item], channel, "<remove>", mach_reference)[0]
    except ModelSpecError:
        return None


def apply_channel(table: dict, channel: str, parent: ChannelModel | None, src: str,
                  mach_reference: float = 12.4) -> tuple[ChannelModel, ChannelChange]:
    """One channel table applied to the parent's model of that channel."""
    if not isinstance(table, dict):
        raise ModelSpecError(f"{src}: [{channel}] must be a table with terms = [...], add = [...] or remove = [...]")
    unknown = sorted(set(table) - set(KEYS))
    if unknown:
        raise ModelSpecError(f"{src}: [{channel}] unknown key(s) {unknown}; a channel table has {', '.join(KEYS)}")
    terms, add, remove = (_items(table, k, channel, src) for k in KEYS)
    if terms is None and add is None and remove is None:
        raise ModelSpecError(f"{src}: [{channel}] needs terms = [...] (replace the model), add = [...] or "
                             "remove = [...] (relative to the parent version)")
    replaced, dropped = terms is not None, ()
    if replaced:
        if not terms:
            raise ModelSpecError(f"{src}: [{channel}] terms = [] leaves the channel without terms")
        current = list(parse_terms(terms, channel, src, mach_reference))
        if parent is not None:
            kept = {t.coefficient for t in current}
            dropped = tuple(t.coefficient for t in parent.terms if t.coefficient not in kept)
    elif parent is None:
        raise ModelSpecError(f"{src}: [{channel}] add/remove need a parent model of {channel}, and there is none; "
                             "give the whole model with terms = [...]")
    else:
        current = list(parent.terms)
    removed = []
    for item in remove or ():
        named = _named(item, channel, mach_reference)
        hit = [t for t in current if _matches(t, item, named)]
        if not hit:
            have = ", ".join(term_label(t) for t in current)
            raise ModelSpecError(f"{src}: [{channel}] remove: {item!r} is not a term of the model (its terms: {have})")
        current = [t for t in current if t not in hit]
        removed += [term_label(t) for t in hit]
    added, already = [], []
    for t in parse_terms(add or [], channel, src, mach_reference):
        same = next((c for c in current if c.coefficient == t.coefficient), None)
        if same is None:
            current.append(t)
            added.append(term_label(t))
        elif same.expression.replace(" ", "") == t.expression.replace(" ", ""):
            already.append(term_label(t))
        else:
            raise ModelSpecError(f"{src}: [{channel}] add: coefficient {t.coefficient} is already in the model as "
                                 f"{term_label(same)!r}; remove it first (remove = [\"{t.coefficient}\"]) or give "
                                 "the new term another name")
    if not current:
        raise ModelSpecError(f"{src}: [{channel}] remove leaves the channel without terms")
    if len(current) > MAX_TERMS:
        raise ModelSpecError(f"{src}: [{channel}] {len(current)} terms: at most {MAX_TERMS} per channel")
    if replaced:
        added = [term_label(t) for t in current if parent is None or t not in parent.terms]
    return (ChannelModel(channel, tuple(current)),
            ChannelChange(channel, replaced, tuple(added), tuple(removed), dropped, tuple(already)))


def apply_spec(doc: dict, base: dict | None, source: str = "<memory>", mach_reference: float = 12.4) -> SpecResult:
    """A parsed spec document applied to the base models (None: the default models)."""
    models = dict(default_models() if base is None else base)
    changes = []
    for channel, table in doc.items():
        if channel not in CHANNELS:
            raise ModelSpecError(f"{source}: unknown channel [{channel}]; channels: {', '.join(CHANNELS)}")
        models[channel], change = apply_channel(table, channel, models.get(channel), source, mach_reference)
        changes.append(change)
    return SpecResult(models, tuple(changes), source)


def read_spec(path: str | Path, base: dict | None = None, mach_reference: float = 12.4) -> SpecResult:
    """Read a TOML spec file and apply it to `base` (None: the default models)."""
    from aerosid.vehicles.vehicle import read_toml_file

    src = str(path)
    if not Path(path).exists():
        raise ModelSpecError(f"{src}: no such model specification file")
    doc = read_toml_file(Path(path), MAX_SPEC_BYTES, lambda msg: ModelSpecError(f"{src}: {msg}"))
    return apply_spec(doc, base, src, mach_reference)
