"""A static reading of every import statement in the package folders (module level and inside functions), and the
dependency rules README.md and docs/architecture.md state, checked on that reading (tests/test_import_contract.py).

It shares no code with the package: it parses the source with :mod:`ast` and maps folders to ``hilbench.*`` names
the way setup.py installs them."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

PACKAGES = ("bench", "drivers", "firmware_sim", "analysis")
#: the bottom layer (under the namespace root): every package may import it, it imports nothing else of hilbench
COMMON = "hilbench.common"
#: its folder, relative to the repository root
COMMON_DIR = ("hilbench", "common")
#: what a simulated device may take from drivers: the protocol definitions only
PROTOCOL_DEFINITIONS = ("hilbench.drivers.protocol", "hilbench.drivers.cia402", "hilbench.drivers.odrive_can")


@dataclass(frozen=True)
class Edge:
    source: str  # importing module, e.g. hilbench.bench.cli.commands.identify
    target: str  # imported module (or name under it), e.g. hilbench.analysis.record
    where: str  # file:line

    def __str__(self) -> str:
        return f"{self.where}: {self.source} imports {self.target}"


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    if tuple(parts[:2]) == COMMON_DIR:  # hilbench/common/... is already under the namespace
        return ".".join(parts)
    return ".".join(["hilbench", *parts])


def _package_files(root: Path) -> list[Path]:
    """Every module of the package folders and of the bottom layer under ``root``."""
    files = [p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))]
    return files + sorted(root.joinpath(*COMMON_DIR).rglob("*.py"))


def edges(root: Path) -> list[Edge]:
    """Every ``hilbench.*`` import in the package folders under ``root``, at any depth of the code."""
    out: list[Edge] = []
    for path in _package_files(root):
        source = module_name(root, path)
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative: resolve against the importing module's package
                    base = source.split(".")
                    base = base if is_pkg else base[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                targets = [f"{mod}.{a.name}" for a in node.names] if mod else []
                targets = targets or [mod]
            for t in targets:
                if t.startswith("hilbench."):
                    out.append(Edge(source, t, f"{path.relative_to(root)}:{node.lineno}"))
    return out


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def violations(all_edges: list[Edge]) -> list[str]:
    """The broken rules, one line per offending import."""
    bad: list[str] = []
    for e in all_edges:
        s, t = e.source, e.target
        if _under(s, COMMON) and not _under(t, COMMON):
            bad.append(f"{e} (hilbench.common, the bottom layer, imports nothing else of hilbench)")
        if _under(s, "hilbench.drivers") and any(_under(t, f"hilbench.{p}") for p in ("bench", "analysis",
                                                                                       "firmware_sim")):
            bad.append(f"{e} (drivers never imports bench, analysis or the simulators)")
        if _under(s, "hilbench.analysis") and any(_under(t, f"hilbench.{p}") for p in ("bench", "drivers")):
            bad.append(f"{e} (analysis never imports bench and never touches a device)")
        if _under(s, "hilbench.firmware_sim"):
            if any(_under(t, f"hilbench.{p}") for p in ("bench", "analysis")):
                bad.append(f"{e} (a simulated device never imports bench or analysis)")
            if _under(t, "hilbench.drivers") and not any(_under(t, p) for p in PROTOCOL_DEFINITIONS):
                bad.append(f"{e} (a simulated device shares only protocol definitions with drivers)")
        cli = _under(t, "hilbench.bench.cli.commands") or _under(t, "hilbench.bench.cli")
        if _under(s, "hilbench.bench.gui") and cli:
            bad.append(f"{e} (the GUI is an adapter over the analyses, never over the CLI)")
        # The layout's layers: the CLI and the GUI are adapters on top; acquisition (protocols, runner, campaigns) sits
        # on storage (imports, output files); the engine (the C plant) sits under the simulated devices.
        lower = ("hilbench.bench.acquisition", "hilbench.bench.storage", "hilbench.bench.campaign_analysis")
        if any(_under(s, p) for p in lower) and (cli or _under(t, "hilbench.bench.gui")):
            bad.append(f"{e} (acquisition, storage and campaign analysis never import the CLI or the GUI)")
        if _under(s, "hilbench.bench.storage") and _under(t, "hilbench.bench.acquisition"):
            bad.append(f"{e} (storage never imports acquisition)")
        if _under(s, "hilbench.firmware_sim.engine") and _under(t, "hilbench.firmware_sim.devices"):
            bad.append(f"{e} (the simulation engine never imports the simulated devices)")
        if (_under(s, "hilbench.bench.cli.commands") and _under(t, "hilbench.bench.cli.commands")
                and not _under(t, s) and s != "hilbench.bench.cli.commands"):
            bad.append(f"{e} (CLI commands never import each other)")
    return bad


def module_graph(all_edges: list[Edge], modules: set[str]) -> dict[str, set[str]]:
    """Module -> the modules it imports (an imported name resolves to its module)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for e in all_edges:
        t = e.target
        while t and t not in modules:
            t = t.rpartition(".")[0]
        if t and t != e.source and not _under(e.source, t):  # a package's own __init__ is not a cycle
            graph[e.source].add(t)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def modules(root: Path) -> set[str]:
    return {module_name(root, p) for p in _package_files(root)}


def check(root: Path) -> list[str]:
    """Every broken rule and every import cycle in the tree at ``root``, one line each."""
    es = edges(root)
    mods = modules(root)
    graph = module_graph(es, mods)
    # a package's __init__ re-exporting its own submodules is not a dependency between modules
    for m in mods:
        graph[m] = {t for t in graph[m] if not _under(t, m)}
    return violations(es) + [f"import cycle: {' <-> '.join(c)}" for c in cycles(graph)]
