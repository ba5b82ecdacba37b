"""``iloci plugins``: everything registered (components, fold executors, robots), who
registered it and whether it can be built."""

from __future__ import annotations

import argparse
import json

from iloci.interfaces import ALL_KINDS
from iloci.plugins import get_plugin_manager, get_registry, plugin_infos


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plugins", help="list registered components and their back ends")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def rows() -> tuple[list[dict], list[dict]]:
    """(component rows, plugins not loaded: failed, blocked or not autoloaded)."""
    pm = get_plugin_manager()
    registry = get_registry(pm)
    out = []
    for spec in [s for kind in ALL_KINDS for s in registry.specs(kind)]:
        missing = spec.missing()
        out.append({
            "kind": ALL_KINDS[spec.kind].label, "name": spec.name,
            "distribution": spec.distribution or "-", "version": spec.version or "-",
            "status": "available" if not missing else
            f"missing {', '.join(missing)}: {spec.install or 'pip install ' + ' '.join(missing)}",
            "summary": spec.summary,
            "here": spec.description(),
            **({"facts": dict(spec.facts)} if spec.facts else {}),
        })
    broken = [{"plugin": i.name, "distribution": i.distribution, "status": i.status,
               "error": i.error, "why": i.why_unloaded}
              for i in plugin_infos(pm).values() if i.status != "loaded"]
    return out, broken


def run(args: argparse.Namespace) -> int:
    table, broken = rows()
    if args.json:
        print(json.dumps({"components": table,
                          "failed_plugins": [b for b in broken if b["status"] == "failed"],
                          "unloaded_plugins": [b for b in broken if b["status"] != "failed"]},
                         indent=2))
        return 0
    cols = ("kind", "name", "distribution", "version", "status")
    widths = {c: max(len(c), *(len(str(r[c])) for r in table)) if table else len(c)
              for c in cols}
    print("  ".join(c.upper().ljust(widths[c]) for c in cols).rstrip())
    for r in table:
        print("  ".join(str(r[c]).ljust(widths[c]) for c in cols).rstrip())
    for r in table:
        if r["here"]:
            print(f"{r['kind']} {r['name']}: {r['here']}")
    for b in broken:
        if b["status"] == "failed":
            print(f"failed: plugin {b['plugin']!r} ({b['distribution']}): {b['error']}")
        else:
            print(f"{b['status']}: {b['why']}")
    return 0
