#!/usr/bin/env python3
"""The house's rules (docs/architecture.md), checked on every #include "..." of the rooms:

1. a room includes only itself and the rooms it may depend on (the table below), so nothing
   runs up a floor and nothing reaches sideways;
2. `cli/` sees the daemon only through its face (FACE): the control API's client, the
   configuration, campaign plans and the simulated-lab runner, never the daemon's insides;
3. no circle of includes between units (a .hpp and its .cpp are one unit).

Prints every breach with file and line; exit 1 if there is one.
Usage: check_rooms.py <source root> | check_rooms.py --self-test (a made-up house with one breach
of each rule: all three must be found, so this check cannot pass by finding nothing).
"""
import re
import sys
from pathlib import Path

MAY_USE = {
    "base": set(),
    "protocol": set(),
    "physics": set(),
    "drivers": {"protocol", "base"},
    "sim": {"protocol", "physics"},
    "analysis": {"physics", "base"},
    "store": {"analysis", "protocol", "base"},
    "archive": {"store", "analysis", "base"},
    "daemon": {"archive", "store", "analysis", "sim", "drivers", "physics", "protocol", "base"},
    "cli": {"daemon", "archive", "store", "analysis", "sim", "drivers", "physics", "protocol", "base"},
}
FACE = {"daemon/config.hpp", "daemon/campaign_plan.hpp", "daemon/control_client.hpp", "daemon/simulated_lab.hpp",
        "daemon/virtual_run.hpp"}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def check(root: Path, min_files: int = 50) -> list:
    breaches = []
    edges = {}  # unit -> set of units
    files = [p for room in MAY_USE for p in sorted((root / room).rglob("*")) if p.suffix in (".cpp", ".hpp")]
    if len(files) < min_files:
        return [f"only {len(files)} source files under {root}: wrong root?"]
    for path in files:
        rel = path.relative_to(root).as_posix()
        room = rel.split("/", 1)[0]
        unit = rel.rsplit(".", 1)[0]
        for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            m = INCLUDE.match(line)
            if not m:
                continue
            target = m.group(1)
            target_room = target.split("/", 1)[0]
            if target_room not in MAY_USE:
                continue  # a generated or system header
            if not (root / target).is_file():
                breaches.append(f"{rel}:{lineno}: includes {target}, which does not exist")
                continue
            if target_room != room and target_room not in MAY_USE[room]:
                breaches.append(f"{rel}:{lineno}: {room}/ may not include {target} "
                                f"({room}/ may use: {', '.join(sorted(MAY_USE[room])) or 'nothing'})")
            if room == "cli" and target_room == "daemon" and target not in FACE:
                breaches.append(f"{rel}:{lineno}: cli/ includes the daemon's insides ({target}); "
                                f"its face is {', '.join(sorted(FACE))}")
            target_unit = target.rsplit(".", 1)[0]
            if target_unit != unit:
                edges.setdefault(unit, set()).add(target_unit)
    # Circles: Tarjan's strongly connected components over units.
    index, low, stack, on_stack, circles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    sys.setrecursionlimit(10000)
    for v in sorted(edges):
        if v not in index:
            visit(v)
    for c in circles:
        breaches.append("a circle of includes: " + " -> ".join(c))
    units = len({p.relative_to(root).as_posix().rsplit(".", 1)[0] for p in files})
    print(f"check_rooms: {len(files)} files ({units} units) in {len(MAY_USE)} rooms under {root}")
    return breaches


def self_test() -> int:
    import tempfile
    house = {
        "daemon/lab.hpp": "",
        "physics/up.hpp": '#include "daemon/lab.hpp"\n',          # runs up a floor
        "cli/cmd.cpp": '#include "daemon/lab.hpp"\n',             # the daemon's insides
        "analysis/p.hpp": '#include "analysis/q.hpp"\n',          # a circle
        "analysis/q.hpp": "",
        "analysis/q.cpp": '#include "analysis/p.hpp"\n',
        "store/fine.cpp": '#include "analysis/p.hpp"\n#include "base/e.hpp"\n',  # allowed
        "base/e.hpp": "",
    }
    with tempfile.TemporaryDirectory() as tmp:
        for rel, text in house.items():
            (Path(tmp) / rel).parent.mkdir(parents=True, exist_ok=True)
            (Path(tmp) / rel).write_text(text)
        found = check(Path(tmp), min_files=1)
    for b in found:
        print("  found:", b)
    expected = ["physics/up.hpp:1: physics/ may not include daemon/lab.hpp",
                "cli/cmd.cpp:1: cli/ includes the daemon's insides", "a circle of includes: analysis/p -> analysis/q"]
    missing = [e for e in expected if not any(b.startswith(e) for b in found)]
    for m in missing:
        print("NOT FOUND:", m)
    if len(found) != len(expected):
        print(f"expected exactly {len(expected)} breaches, found {len(found)}")
    return 1 if missing or len(found) != len(expected) else 0


def main() -> int:
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    breaches = check(Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve())
    for b in breaches:
        print(b)
    print(f"check_rooms: {len(breaches)} breaches")
    return 1 if breaches else 0


if __name__ == "__main__":
    sys.exit(main())
