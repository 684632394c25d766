"""Shared by the pick tests: the demonstrator's scenario (Hamburg table, arm, box)."""

import pytest

from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario

PATH = diagrams_dir() / "hamburg_setup.yaml"


@pytest.fixture(scope="module")
def hamburg():
    return LoadScenario(filename=PATH)
