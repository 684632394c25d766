"""Only here to add models/ and diagrams/ as package data (`handle_drake._models`,
`handle_drake._diagrams`).

pyproject.toml holds all metadata; setuptools cannot list a package whose
directory lies outside the package tree from pyproject alone. Every directory
that holds data (e.g. ``models/objects/mug``, ``handle_drake/grasp/data``) is
listed as a namespace package too: setuptools includes their files through the
``package-data`` globs, and warns (and plans to stop) when such a directory is
importable but not listed.
"""

from setuptools import find_namespace_packages, setup

_SKIP = ["__pycache__", "*.__pycache__"]


def _under(directory: str, package: str) -> list[str]:
    """``package`` and every directory below ``directory`` as its subpackages."""
    return [package] + [f"{package}.{name}"
                        for name in find_namespace_packages(where=directory, exclude=_SKIP)]


setup(packages=_under("handle_drake", "handle_drake") + _under("models", "handle_drake._models")
      + _under("diagrams", "handle_drake._diagrams"))
