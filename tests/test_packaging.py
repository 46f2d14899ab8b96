"""Package metadata: the license in the SPDX form of PEP 639, which setuptools 77 and later
read without their deprecation banner (a TOML table ``license = {text = ...}`` prints it)."""

import pytest
from conftest import ROOT


def test_license_is_an_spdx_expression_with_its_file():
    tomllib = pytest.importorskip("tomllib")
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    project = meta["project"]
    assert project["license"] == "MIT"
    assert all((ROOT / name).is_file() for name in project["license-files"])
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    assert "setuptools>=77" in meta["build-system"]["requires"]
