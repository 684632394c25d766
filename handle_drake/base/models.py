"""Where the project's models live and how Drake finds them.

``models/`` is a Drake package named ``handle_drake_models`` (see its
``package.xml``); model files refer to each other as
``package://handle_drake_models/...``. In a checkout it sits at the top of the
repository; ``pip install .`` installs it as ``handle_drake/_models``.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

PACKAGE_NAME = "handle_drake_models"


# The package's own folder (handle_drake/), wherever this module sits inside it.
PACKAGE_DIR = Path(__file__).resolve().parents[1]


@cache
def models_dir() -> Path:
    """The directory holding ``package.xml`` of ``handle_drake_models``."""
    here = PACKAGE_DIR
    for candidate in (here.parent / "models", here / "_models"):
        if (candidate / "package.xml").is_file():
            return candidate
    raise FileNotFoundError(
        f"handle_drake models not found: looked for package.xml in {here.parent / 'models'} "
        f"and {here / '_models'}; reinstall handle_drake (pip install .)"
    )


def diagrams_dir() -> Path:
    """``diagrams/`` of a checkout, or its installed copy ``handle_drake/_diagrams``."""
    here = PACKAGE_DIR
    for candidate in (here.parent / "diagrams", here / "_diagrams"):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"no diagrams/ directory next to {here}")


#: What a scenario argument that names no file is told (the CLI's one-line error).
SHIPPED_HINT = ("the shipped scenarios are installed with the package: `handle-drake diagrams "
                "list` names them, `handle-drake simulate NAME` runs one by name, `handle-drake "
                "diagrams copy DEST` copies them to edit")


def shipped_path(path) -> Path:
    """``path`` if something is there; else the installed copy of a shipped file it names.

    The README's ``diagrams/NAME.yaml`` (and ``diagrams/meshes/...``) works outside a
    checkout (a wheel: ``handle_drake/_diagrams``), and a bare ``NAME`` or ``NAME.yaml``
    names a shipped scenario from any folder. A file in the working directory always wins.
    Anything else comes back unchanged (its reader says it is not found).
    """
    given = Path(path)
    if str(path) == "" or given.exists() or given.is_absolute():
        return given
    parts = given.parts
    if len(parts) > 1 and parts[0] == "diagrams":
        relative = Path(*parts[1:])
    elif len(parts) == 1:
        relative = given if given.suffix else given.with_name(f"{given.name}.yaml")
    else:
        return given
    try:
        candidate = diagrams_dir() / relative
    except FileNotFoundError:
        return given
    return candidate if candidate.is_file() else given


def shipped_scenarios() -> list[Path]:
    """The shipped scenario files, by name."""
    return sorted(diagrams_dir().glob("*.yaml"))


def model_path(relative: str) -> Path:
    """Absolute path of a file inside ``models/``; raises if it does not exist."""
    path = models_dir() / relative
    if not path.is_file():
        raise FileNotFoundError(f"no model file {relative!r} in {models_dir()}")
    return path


def package_url(relative: str) -> str:
    """``package://handle_drake_models/<relative>`` for Drake's parser."""
    model_path(relative)
    return f"package://{PACKAGE_NAME}/{relative}"


def add_package(parser) -> None:
    """Register ``handle_drake_models`` with a ``pydrake.multibody.parsing.Parser``."""
    package_map = parser.package_map()
    if not package_map.Contains(PACKAGE_NAME):
        package_map.Add(PACKAGE_NAME, str(models_dir()))
