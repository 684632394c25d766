"""The gate of the package's layers (docs/ARCHITECTURE.md, "Layers").

Every module of ``handle_drake`` is parsed (not imported) and each import of another
``handle_drake`` module is checked:

- it runs downwards: to a lower layer, or inside its own unit (one layer package; one
  device of ``devices/``; one application of ``apps/``); never sideways to a peer of the
  same rank, never upwards;
- it sits at the top of the module, not inside a function, except in the command-line
  modules (``cli.py``, ``__main__.py``, ``apps/cli_support.py``,
  ``apps/perception/perceive.py``), which import an area's code only when its sub-command
  runs (``handle-drake`` pins BLAS before any of them loads numpy).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "handle_drake"

# (module prefix, rank). Longest prefix wins; equal ranks are peers that may not import
# each other.
LAYERS: tuple[tuple[str, float], ...] = (
    ("handle_drake.base", 0),
    ("handle_drake.geometry", 1),
    ("handle_drake.learning", 1),
    ("handle_drake.grasp", 2),
    # generic simulated drivers and controllers; a device's wiring may build on them (the
    # PA10 arm's driver is the hand's PD driver with the arm's limits)
    ("handle_drake.systems", 2.9),
    ("handle_drake.devices", 3),
    # the scene around the hand: several objects and the sorting box (config and geometry
    # of a scenario's objects, below scenario; their models in a plant, below station)
    ("handle_drake.scene", 3.5),
    ("handle_drake.scenario", 4),
    ("handle_drake.station", 5),
    ("handle_drake.trial", 6),
    ("handle_drake.apps.cli_support", 6.5),  # what every command shares
    # the camera's estimate of a tabletop object, which the planning command's --perceived
    # plans on: below the other applications
    ("handle_drake.apps.perception", 6.8),
    ("handle_drake.apps", 7),
    # gymnasium environments of the applications' tasks (in-hand, grasp): above them
    ("handle_drake.envs", 7.5),
    ("handle_drake.cli", 8),
)
# Layers whose sub-packages are units of their own (one device, one application).
SPLIT = ("handle_drake.devices", "handle_drake.apps")
# The commands' shared helpers are command-line code too: `handle-drake` pins BLAS before
# any area module loads numpy, so what every command imports stays light.
CLI_MODULES = ("handle_drake.cli", "handle_drake.apps.cli_support",
               "handle_drake.apps.perception.perceive")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer_of(module: str) -> tuple[str, float] | None:
    best = None
    for prefix, rank in LAYERS:
        if module == prefix or module.startswith(prefix + "."):
            if best is None or len(prefix) > len(best[0]):
                best = (prefix, rank)
    return best


def unit_of(module: str) -> str | None:
    layer = layer_of(module)
    if layer is None:
        return None
    prefix = layer[0]
    if prefix in SPLIT and module != prefix:
        return ".".join(module.split(".")[: prefix.count(".") + 2])
    return prefix


def is_cli(module: str) -> bool:
    last = module.rsplit(".", 1)[-1]
    return last in ("cli", "__main__") or module in CLI_MODULES


def package_imports(path: Path):
    """(imported module, line, inside a function) of every handle_drake import."""
    module = module_name(path)
    is_pkg = path.name == "__init__.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                      ast.Lambda))
            if isinstance(child, ast.Import):
                found.extend((a.name, child.lineno, in_function) for a in child.names
                             if a.name.split(".")[0] == "handle_drake")
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    parts = module.split(".")[: None if is_pkg else -1]
                    parts = parts[: len(parts) - (child.level - 1)]
                    base = ".".join(parts + ([base] if base else []))
                if base.split(".")[0] == "handle_drake":
                    for a in child.names:
                        sub = f"{base}.{a.name}"
                        target = sub if _is_module(sub) else base
                        found.append((target, child.lineno, in_function))
            visit(child, inner)

    visit(tree, False)
    return found


def _is_module(name: str) -> bool:
    rel = Path(*name.split(".")[1:])
    return (PACKAGE / rel).with_suffix(".py").is_file() or (PACKAGE / rel / "__init__.py").is_file()


def allowed(importer: str, imported: str) -> bool:
    """The rule: inside one unit, or down to a strictly lower layer. No exception for the
    command-line modules: a device's own command (``can-sim``, ``can-server``) takes its
    argument types from ``base/arguments.py``, not from ``apps/cli_support`` above it."""
    return unit_of(imported) == unit_of(importer) or layer_of(imported)[1] < layer_of(importer)[1]


def violations() -> tuple[list[str], list[str]]:
    upward, in_function = [], []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = module_name(path)
        layer = layer_of(module)
        for target, line, in_func in package_imports(path):
            where = f"{path.relative_to(PACKAGE.parent)}:{line}: {module} -> {target}"
            if in_func and not is_cli(module):
                in_function.append(where)
            target_layer = layer_of(target)
            if layer is None or target_layer is None:
                if target != "handle_drake" and module != "handle_drake":
                    upward.append(where + " (module in no layer)")
                continue
            if not allowed(module, target):
                upward.append(where)
    return upward, in_function


def test_every_module_is_in_a_layer():
    loose = [module_name(p) for p in PACKAGE.rglob("*.py")
             if layer_of(module_name(p)) is None and module_name(p) != "handle_drake"]
    assert loose == []


def test_imports_run_downwards_only():
    upward, _ = violations()
    assert upward == [], f"{len(upward)} imports that are not downwards:\n" + "\n".join(upward)


def test_no_imports_inside_functions_outside_the_commands():
    _, in_function = violations()
    assert in_function == [], (f"{len(in_function)} imports inside functions:\n"
                               + "\n".join(in_function))


@pytest.mark.parametrize(("importer", "imported", "expected"), [
    ("handle_drake.station", "handle_drake.scenario", True),
    ("handle_drake.scenario", "handle_drake.station", False),
    ("handle_drake.geometry.objects.plant", "handle_drake.learning.gp", False),  # peers
    ("handle_drake.devices.midi.codec", "handle_drake.devices.midi.mapping", True),
    ("handle_drake.devices.midi.codec", "handle_drake.devices.can_hand.config", False),
    ("handle_drake.apps.inhand.task", "handle_drake.apps.cli_support", True),
    ("handle_drake.apps.inhand.task", "handle_drake.apps.figure9.cli", False),
    # a device's command may not reach up to the applications' shared helpers (issue 48)
    ("handle_drake.devices.can_hand.cli", "handle_drake.apps.cli_support", False),
    ("handle_drake.devices.can_hand.cli", "handle_drake.base.arguments", True),
    ("handle_drake.apps.inhand.cli", "handle_drake.base.arguments", True),
])
def test_the_rule_itself(importer, imported, expected):
    """The rule the gate applies, on known cases (so that the gate cannot pass vacuously)."""
    assert allowed(importer, imported) == expected


def test_the_gate_catches_an_upward_import_from_a_command_module(tmp_path, monkeypatch):
    """A device's cli.py importing apps/cli_support is reported (it was exempted before)."""
    import shutil

    package = tmp_path / "handle_drake"
    for rel in ("__init__.py", "base/__init__.py", "base/arguments.py", "apps/__init__.py",
                "apps/cli_support.py", "devices/__init__.py", "devices/can_hand/__init__.py"):
        (package / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(PACKAGE / rel, package / rel)
    (package / "devices/can_hand/cli.py").write_text(
        "from handle_drake.apps.cli_support import non_empty\n")
    monkeypatch.setitem(globals(), "PACKAGE", package)
    upward, _ = violations()
    assert upward == ["handle_drake/devices/can_hand/cli.py:1: handle_drake.devices.can_hand.cli"
                      " -> handle_drake.apps.cli_support"]
    (package / "devices/can_hand/cli.py").write_text(
        "from handle_drake.base.arguments import non_empty\n")
    assert violations() == ([], [])


# ----------------------------------------------------------- function length
MAX_FUNCTION_LINES = 80
# Functions still longer (issue 32), with their length when listed: each may only shrink
# (and leaves this list once it is <= MAX_FUNCTION_LINES); no other function may grow past.
LONG_FUNCTIONS: dict[str, int] = {}


def function_lengths(source: str) -> dict[str, int]:
    """Lines of each function and method (``Class.method``; nested ones too), def to end."""
    lengths: dict[str, int] = {}

    def visit(node, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = prefix + child.name
                if not isinstance(child, ast.ClassDef):
                    lengths[name] = child.end_lineno - child.lineno + 1
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return lengths


def long_functions() -> dict[str, int]:
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).as_posix()
        for name, n in function_lengths(path.read_text()).items():
            if n > MAX_FUNCTION_LINES:
                found[f"{rel}::{name}"] = n
    return found


def test_no_function_over_80_lines():
    found = long_functions()
    new = {k: n for k, n in found.items() if k not in LONG_FUNCTIONS}
    assert new == {}, f"functions over {MAX_FUNCTION_LINES} lines: {new}"
    grown = {k: (LONG_FUNCTIONS[k], n) for k, n in found.items() if n > LONG_FUNCTIONS.get(k, n)}
    assert grown == {}, f"listed long functions grew (listed, now): {grown}"
    fixed = sorted(set(LONG_FUNCTIONS) - set(found))
    assert fixed == [], f"no longer over {MAX_FUNCTION_LINES} lines, drop from the list: {fixed}"


def test_function_lengths_counts_methods_and_nested_functions():
    source = "def f():\n    def g():\n        pass\n    return g\n\n\nclass A:\n" \
             "    def m(self):\n        x = 1\n        return x\n"
    assert function_lengths(source) == {"f": 4, "f.g": 2, "A.m": 3}


def test_the_architecture_document_stays_a_design_of_at_most_400_lines():
    """docs/ARCHITECTURE.md is the design; measurements belong in docs/results/ (issue 48)."""
    lines = (PACKAGE.parent / "docs" / "ARCHITECTURE.md").read_text().splitlines()
    assert len(lines) <= 400, f"docs/ARCHITECTURE.md: {len(lines)} lines, at most 400"
