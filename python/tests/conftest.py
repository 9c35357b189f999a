import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture
def scripts():
    """The repository's scripts/ folder."""
    return ROOT / "scripts"


@pytest.fixture
def examples():
    """The repository's examples/ folder."""
    return ROOT / "examples"
