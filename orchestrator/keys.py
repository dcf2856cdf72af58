"""`immerse keys [TABLE]`: the reference of every case.toml key, read from the case schema itself
(orchestrator/schema): its path, type or allowed values, unit, range, default and meaning, as
LAMMPS's `lmp -h` or OpenFOAM's `foamDictionary` print theirs.  The README's key reference is this
output in Markdown (`--markdown`), and a test keeps the two equal: one source for the schema that
refuses a key and the text that explains it.

Paths: ``run.dt_scale``; ``<name>`` a table the user names (``materials.<name>.density``); ``[]``
each table of an array (``lagrange.bodies[].mesh``); ``<face>`` each face of the box (x_lower,
x_upper, y_lower, y_upper, z_lower, z_upper) where all six take the same keys. A key allowed only in
some variants of its table (a material model's parameters, an EOS's) says which (``when model =
'johnson_cook'``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field


@dataclass
class Key:
    path: str
    kind: str                    # number, integer, string, boolean, table, array, list of ..., one of ...
    unit: str | None = None
    allowed: str = ""            # enum values or the range
    default: object = None
    has_default: bool = False
    meaning: str = ""
    when: list[str] = field(default_factory=list)


def _kind(node: dict) -> str:
    if "enum" in node:
        return "one of"
    if "const" in node:
        return "constant"
    t = node.get("type")
    if isinstance(t, list):
        return " or ".join(t)
    if t == "object":
        return "table"
    if t == "array":
        items = node.get("items")
        if isinstance(items, dict) and items.get("type") == "object":
            return "array of tables"
        if isinstance(items, dict) and items.get("type"):
            return f"list of {items['type']}s" + (f" ({node['minItems']}-{node['maxItems']})"
                                                  if "minItems" in node and "maxItems" in node else "")
        return "list"
    if t:
        return t
    if "oneOf" in node or "anyOf" in node:
        return "one of the forms below"
    return "value"


def _range(node: dict) -> str:
    if "enum" in node:
        return ", ".join(repr(v) for v in node["enum"])
    physical = set(node.get("x-physical", ()))
    parts = []
    for key, op in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<")):
        if key in node and key not in physical:
            parts.append(f"{op} {node[key]:g}" if isinstance(node[key], (int, float)) else f"{op} {node[key]}")
    items = node.get("items")
    if isinstance(items, dict) and "enum" in items:
        parts.append("each of " + ", ".join(repr(v) for v in items["enum"]))
    return ", ".join(parts) or node.get("x-allowed", "")


def _walk(node, path: str, out: dict, when: str | None = None) -> None:
    if not isinstance(node, dict):
        return
    for k, v in node.get("properties", {}).items():
        if v is True:          # (a variant's placeholder: the key is described where it is defined)
            continue
        p = f"{path}.{k}" if path else k
        _entry(v, p, out, when)
    for key, suffix in (("additionalProperties", ".<name>"), ("patternProperties", ".<name>")):
        v = node.get(key)
        subs = v.values() if key == "patternProperties" and isinstance(v, dict) else [v]
        for s in subs:
            if isinstance(s, dict) and (s.get("properties") or s.get("allOf") or s.get("oneOf") or s.get("anyOf")):
                _entry(s, path + suffix, out, when, named=True)
    for key in ("allOf", "oneOf", "anyOf"):
        for alt in node.get(key, []):
            if not isinstance(alt, dict):
                continue
            then = alt.get("then")
            if then is not None:     # a variant: its keys are allowed when its condition holds
                cond = then.get("x-when")
                for k in then.get("properties", {}):
                    p = f"{path}.{k}" if path else k
                    if cond and p in out and cond not in out[p].when:
                        out[p].when.append(cond)
                _walk(then, path, out, when)
            else:
                _walk(alt, path, out, when)


def _entry(node: dict, path: str, out: dict, when, named: bool = False) -> None:
    if path not in out:
        out[path] = Key(path, _kind(node), node.get("x-unit"), _range(node), node.get("default"),
                        "default" in node, " ".join(node.get("description", "").split()))
    key = out[path]
    if not key.meaning and node.get("description"):
        key.meaning = " ".join(node["description"].split())
    items = node.get("items")
    if isinstance(items, dict) and (items.get("properties") or items.get("allOf")):
        _walk(items, path + "[]", out, when)
    for alt in node.get("oneOf", []) + node.get("anyOf", []):   # a key of several forms (a name or a table)
        if isinstance(alt, dict):
            _walk(alt, path, out, when)
    _walk({k: v for k, v in node.items() if k not in ("oneOf", "anyOf")}, path, out, when)


def keys(schema: dict | None = None) -> list[Key]:
    """Every key of the case schema, in the schema's order."""
    if schema is None:
        from orchestrator.schema.case import case_schema

        schema = case_schema()
    out: dict[str, Key] = {}
    _walk(schema, "", out)
    # a key every variant of its table allows needs no condition
    variants: dict[str, set] = {}
    for k in out.values():
        variants.setdefault(k.path.rsplit(".", 1)[0], set()).update(k.when)
    for k in out.values():
        if set(k.when) == variants[k.path.rsplit(".", 1)[0]]:
            k.when = []
    return _faces(list(out.values()))


_FACE = re.compile(r"\.[xyz]_(?:lower|upper)(?=\.|$)")


def _faces(all_keys: list[Key]) -> list[Key]:
    """The six faces of a box (x_lower ... z_upper) take the same keys: one entry ``<face>`` each,
    when every face's entry says the same."""
    merged: dict[str, Key] = {}
    out = []
    for k in all_keys:
        if not _FACE.search(k.path):
            out.append(k)
            continue
        path = _FACE.sub(".<face>", k.path)
        same = Key(path, k.kind, k.unit, k.allowed, k.default, k.has_default, k.meaning, list(k.when))
        if path not in merged:
            merged[path] = same
            out.append(same)
        elif merged[path] != same:   # faces that differ keep their own entries
            out.append(k)
    return out


def tables(all_keys: list[Key]) -> list[str]:
    return list(dict.fromkeys(k.path.split(".")[0].split("[")[0] for k in all_keys))


def select(all_keys: list[Key], table: str | None) -> list[Key]:
    """The keys under ``table`` (a dotted prefix: ``run``, ``ale.materials``); ValueError if none."""
    if not table:
        return all_keys
    t = table.rstrip(".")
    chosen = [k for k in all_keys if k.path == t or k.path.startswith((t + ".", t + "["))]
    if not chosen:
        raise ValueError(f"TABLE = {table!r}: no such key or table; tables: {', '.join(tables(all_keys))}")
    return chosen


def _unit(u: str | None) -> str:
    return "" if u is None else ("-" if u == "dimensionless" else u)


def text(chosen: list[Key]) -> str:
    """The plain reference: one block per key."""
    lines = []
    for k in chosen:
        head = f"{k.path}  [{k.kind}" + (f", {_unit(k.unit)}" if k.unit else "") + "]"
        if k.allowed:
            head += f"  {k.allowed}"
        if k.has_default:
            head += f"  default {k.default!r}"
        lines.append(head)
        if k.when:
            lines.append(f"    only when {' or '.join(k.when)}")
        if k.meaning:
            lines.append(f"    {k.meaning}")
    return "\n".join(lines) + "\n"


def markdown(chosen: list[Key]) -> str:
    """The README's reference: one table per top-level table of case.toml."""
    out = []
    for t in tables(chosen):
        rows = [k for k in chosen if k.path.split(".")[0].split("[")[0] == t]
        out.append(f"#### `[{t}]`\n\n| key | type | unit | allowed | default | meaning |\n|---|---|---|---|---|---|")
        for k in rows:
            meaning = k.meaning + (f" (only when {' or '.join(k.when)})" if k.when else "")
            default = f"`{k.default!r}`" if k.has_default else ""
            cells = [f"`{k.path}`", k.kind, _unit(k.unit), k.allowed, default, meaning]
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
    return "\n".join(out)


__all__ = ["Key", "keys", "select", "tables", "text", "markdown"]
