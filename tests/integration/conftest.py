"""Session fixtures: the tiny pythonfmu test FMUs, built once, and scenario writing helpers."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmu_helpers import build_test_fmus  # noqa: E402


@pytest.fixture(scope="session")
def test_fmus(tmp_path_factory) -> dict[str, Path]:
    return build_test_fmus(tmp_path_factory.mktemp("fmus"))


@pytest.fixture
def write_scenario(tmp_path, test_fmus):
    """Write a scenario; ``{NAME}`` placeholders become the test FMU paths."""

    def write(text: str, name: str = "s.yaml") -> Path:
        for model, path in test_fmus.items():
            text = text.replace("{" + model + "}", str(path))
        p = tmp_path / name
        p.write_text(text)
        return p

    return write
