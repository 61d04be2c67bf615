"""Importing ``sodyn.jax`` / ``sodyn.torch`` / ``sodyn.casadi`` without its framework raises an
``ImportError`` that names the extra to install (the framework is hidden in a subprocess)."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["jax", "torch", "casadi"])
def test_missing_framework_names_the_extra(module):
    code = (
        "import sys\n"
        f"sys.modules[{module!r}] = None  # makes 'import {module}' fail\n"
        "try:\n"
        f"    import sodyn.{module}\n"
        "except ImportError as e:\n"
        "    print(e)\n"
        "else:\n"
        "    print('imported')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert f"pip install 'sodyn[{module}]'" in out.stdout, out.stdout + out.stderr
    # the numpy API does not need any framework
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            f"import sys; sys.modules[{module!r}] = None; import sodyn; print(sodyn.__version__)",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout.strip()
