"""Shared fixtures."""

from __future__ import annotations

import pytest

from leadthrough.robot import Robot, load_robot


@pytest.fixture(scope="session")
def er20() -> Robot:
    """The built-in ER20-class robot."""
    return load_robot("er20")
