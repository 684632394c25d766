"""Only here to add models/ and diagrams/ as package data (`handle_drake._models`,
`handle_drake._diagrams`).

pyproject.toml holds all metadata; setuptools cannot list a package whose
directory lies outside the package tree from pyproject alone.
"""

from setuptools import find_packages, setup

setup(packages=find_packages(include=["handle_drake", "handle_drake.*"]) + [
    "handle_drake._models",
    "handle_drake._diagrams",
])
