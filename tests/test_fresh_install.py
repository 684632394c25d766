"""What a fresh machine has: every import is declared, every module imports, every command that
the README names answers --help, each in a subprocess of the installed environment.

`.ci/run` installs the project into a new virtual environment, so there a module that a test
finds importable is one that pyproject.toml brings; on a developer's machine a package installed
by hand would pass here, which is why CI makes a new venv every run.
"""

from __future__ import annotations

import ast
import importlib.metadata
import importlib.util
import json
import os
import pkgutil
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import handle_drake

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}


def _package_modules() -> list[str]:
    names = [handle_drake.__name__]
    for info in pkgutil.walk_packages(handle_drake.__path__, prefix="handle_drake."):
        if info.name.rsplit(".", 1)[-1] != "__main__":
            names.append(info.name)
    return sorted(names)


def _python_sources() -> list[tuple[Path, str]]:
    files = [f for d in ("handle_drake", "tests", "benchmarks") for f in (ROOT / d).rglob("*.py")]
    sources = [(f, f.read_text(errors="replace")) for f in files]
    for notebook in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(notebook.read_text())["cells"]
        code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
        sources.append((notebook, re.sub(r"^\s*[!%].*$", "", code, flags=re.M)))
    return sources


def _top_level_imports() -> dict[str, list[str]]:
    """Top-level module name -> where it is imported (absolute imports only)."""
    local = {p.stem for p in (ROOT / "tests").rglob("*.py")}
    local |= {p.stem for p in (ROOT / "benchmarks").rglob("*.py")}
    local |= {"handle_drake", "conftest"}
    found: dict[str, list[str]] = {}
    for path, source in _python_sources():
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules = [node.module]
            else:
                continue
            for module in modules:
                top = module.split(".")[0]
                if top in sys.stdlib_module_names or top in local:
                    continue
                found.setdefault(top, []).append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def test_every_third_party_import_is_installed():
    """Each top-level module imported anywhere (package, tests, benchmarks, notebooks) is
    installed: in CI's new venv that means declared in pyproject.toml."""
    imports = _top_level_imports()
    assert {"numpy", "pydrake", "mido", "trimesh"} <= imports.keys()  # the scan sees imports
    missing = {top: where[:3] for top, where in imports.items()
               if importlib.util.find_spec(top) is None}
    assert not missing, f"imported but not installed (declare in pyproject.toml): {missing}"


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement(text: str) -> tuple[str, list[str]]:
    """(distribution, [extras]) of a requirement string such as 'dask[distributed]>=2024'."""
    match = re.match(r"\s*([A-Za-z0-9_.\-]+)\s*(?:\[([^\]]*)\])?", text)
    extras = [e.strip() for e in (match.group(2) or "").split(",") if e.strip()]
    return _normalized(match.group(1)), extras


def declared_distributions(pyproject: dict) -> set[str]:
    """Distributions pyproject.toml names itself: dependencies, every extra, and what a named
    extra of a dependency adds (``dask[distributed]`` declares ``distributed``)."""
    project = pyproject["project"]
    requirements = list(project.get("dependencies", []))
    for extra in project.get("optional-dependencies", {}).values():
        requirements += extra
    declared = set()
    for requirement in requirements:
        name, extras = _requirement(requirement)
        declared.add(name)
        try:
            for sub in importlib.metadata.requires(name) or []:
                body, _, marker = sub.partition(";")
                named = re.search(r"extra\s*==\s*['\"]([^'\"]+)['\"]", marker)
                if named and named.group(1) in extras:
                    declared.add(_requirement(body)[0])
        except importlib.metadata.PackageNotFoundError:
            pass
    return declared


def undeclared_imports(imports: dict[str, list[str]], declared: set[str],
                       distributions: dict[str, list[str]]) -> dict[str, str]:
    """Top-level module -> why it is not declared: no installed distribution provides it, or
    the ones that do are not named in pyproject.toml (a package that only arrives as a
    dependency's dependency is not declared: it can go away with that dependency)."""
    missing = {}
    for top, where in sorted(imports.items()):
        candidates = {_normalized(d) for d in distributions.get(top, [])}
        if not candidates:
            missing[top] = f"no installed distribution provides it ({', '.join(where[:3])})"
        elif not candidates & declared:
            missing[top] = (f"from {', '.join(sorted(candidates))}, not in pyproject.toml "
                            f"({', '.join(where[:3])})")
    return missing


def test_every_third_party_import_is_declared_in_pyproject():
    """Each third-party module imported by the package, its tests, benchmarks and notebooks'
    code cells comes from a distribution that pyproject.toml names (dependencies or an
    extra), mapped by importlib.metadata.packages_distributions(): true on any machine, not
    only in a new virtual environment."""
    declared = declared_distributions(tomllib.loads((ROOT / "pyproject.toml").read_text()))
    distributions = importlib.metadata.packages_distributions()
    imports = _top_level_imports()
    assert {"PIL", "pydrake", "sklearn", "can", "yaml"} <= imports.keys()  # the scan sees them
    assert not undeclared_imports(imports, declared, distributions)
    # the check itself: without pillow declared, PIL (which matplotlib brings) is reported
    missing = undeclared_imports(imports, declared - {"pillow"}, distributions)
    assert list(missing) == ["PIL"] and "pillow, not in pyproject.toml" in missing["PIL"]
    assert "nowhere_module" in undeclared_imports({"nowhere_module": ["x.py:1"]}, declared,
                                                  distributions)


def test_every_module_of_the_package_imports_in_a_fresh_interpreter():
    modules = _package_modules()
    assert len(modules) > 50 and "handle_drake.cli" in modules
    script = ("import importlib, sys, traceback\n"
              "bad = []\n"
              f"for name in {modules!r}:\n"
              "    try:\n"
              "        importlib.import_module(name)\n"
              "    except BaseException as error:\n"
              "        bad.append(f'{name}: {type(error).__name__}: {error}')\n"
              "print('\\n'.join(bad))\n"
              "sys.exit(1 if bad else 0)\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=300, env=ENV, cwd=ROOT)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]


def _readme_commands() -> list[list[str]]:
    """`handle-drake CMD [SUB]` and `python benchmarks/X.py` as the README writes them."""
    commands: set[tuple[str, ...]] = set()
    for line in README.splitlines():
        line = line.split("#", 1)[0] if not line.lstrip().startswith("#") else ""
        for match in re.finditer(r"handle-drake((?: [a-z][a-z-]*){1,2})", line):
            words = match.group(1).split()
            commands.add(("handle-drake", *words))
        for match in re.finditer(r"python (benchmarks/[a-z_]+\.py)", line):
            commands.add(("python", match.group(1)))
    return [list(c) for c in sorted(commands)]


def _cli() -> str:
    script = Path(sys.executable).parent / "handle-drake"
    return str(script) if script.exists() else shutil.which("handle-drake") or ""


README_COMMANDS = _readme_commands()


def test_the_readme_names_the_commands():
    names = {" ".join(c[1:2]) for c in README_COMMANDS if c[0] == "handle-drake"}
    assert {"demo", "simulate", "babble", "inhand", "midi", "perceive", "grasp"} <= names


@pytest.mark.parametrize("command", README_COMMANDS, ids=" ".join)
def test_every_readme_command_answers_help(command):
    """Run as the installed console script (or the interpreter for benchmarks), the way a user
    types it. A sub-command word the CLI does not know (e.g. `midi jog`) is part of the
    command; a word that is an argument (a file) is dropped."""
    if command[0] == "handle-drake":
        cli = _cli()
        assert cli, "the handle-drake console script is not installed next to this Python"
        argv = [cli, *command[1:]]
    else:
        argv = [sys.executable, str(ROOT / command[1])]
    result = subprocess.run([*argv, "--help"], capture_output=True, text=True, timeout=180,
                            env=ENV, cwd=ROOT)
    if result.returncode == 2 and len(argv) > 2 and "invalid choice" in result.stderr:
        # the last word was an argument, not a sub-command: ask the command itself
        result = subprocess.run([*argv[:-1], "--help"], capture_output=True, text=True,
                                timeout=180, env=ENV, cwd=ROOT)
    assert result.returncode == 0, f"{shlex.join(argv)} --help: {result.stderr[-1500:]}"
    assert "usage:" in result.stdout and "Traceback" not in result.stderr
