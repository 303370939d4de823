"""The package reads top-down: no module imports one that imports it back, and the simulator does
not import the detector (`discrepancy`) that builds on it."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import gyrodenoise

PKG = Path(gyrodenoise.__file__).parent


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports() -> dict[str, set[str]]:
    """module -> gyrodenoise modules it imports (at any depth of the file, lazy imports included)."""
    mods = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("gyrodenoise"):
                targets = [f"{node.module}.{a.name}" for a in node.names]
                deps |= {t if t in mods else node.module for t in targets}
            elif isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name.startswith("gyrodenoise")}
        graph[name] = {d for d in deps if d in mods and d != name}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for d in sorted(graph.get(n, ())):
            if d.endswith("__main__"):
                continue
            if state.get(d) == 1:
                return stack[stack.index(d) :] + [d]
            if d not in state and (c := visit(d)):
                return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (c := visit(n)):
            return c
    return None


def test_no_import_cycle_between_modules():
    graph = _imports()
    # a package's __init__ re-exports its modules; only module-to-module edges form the layering
    edges = {
        n: {d for d in ds if not (PKG / Path(*d.split(".")[1:]) / "__init__.py").exists()} for n, ds in graph.items()
    }
    assert _cycle(edges) is None, _cycle(edges)


def test_simulator_does_not_import_the_detector():
    graph = _imports()
    sim = [n for n in graph if n.startswith("gyrodenoise.sim")]
    bad = {n: sorted(d for d in graph[n] if d.startswith("gyrodenoise.discrepancy")) for n in sim}
    assert not any(bad.values()), bad
    code = "import sys, gyrodenoise.sim; print(any(m.startswith('gyrodenoise.discrepancy') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_importing_the_package_leaves_the_matplotlib_backend_alone():
    """A notebook's inline backend or a user's MPLBACKEND is theirs: the plotting modules build Figure objects
    outside pyplot instead of selecting Agg at import."""
    code = (
        "import matplotlib, gyrodenoise.evaluate, gyrodenoise.discrepancy.report, gyrodenoise.ablation_report; "
        "print(matplotlib.get_backend())"
    )
    env = {**os.environ, "MPLBACKEND": "svg"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.strip() == "svg", out


def test_the_command_modules_leave_lightning_unimported():
    """Lightning's import takes ~8 s on 2 cores: a command refused for its config, `--help`, evaluate and correct do
    not pay it (train imports it in the functions that train)."""
    code = (
        "import sys, gyrodenoise.train, gyrodenoise.evaluate, gyrodenoise.correct, gyrodenoise.cli_errors, "
        "gyrodenoise.discrepancy.__main__; print(sorted({m.split('.')[0] for m in sys.modules} & {'lightning'}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
