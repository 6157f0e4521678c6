"""Defects a new user met in the first hour (issue 23), each pinned by a test that failed before its fix."""

from __future__ import annotations

import subprocess
import sys

import pytest


# -- names that are both a subpackage and an exported function -------------------------------------------------
@pytest.mark.parametrize("first, name", [("read_experiment", "identify"), ("Step", "simulate"),
                                         ("simulate_many", "simulate"), ("Experiment", "identify")])
def test_shared_name_is_the_function_after_its_subpackage_is_imported(first: str, name: str) -> None:
    # a fresh interpreter: importing `first` imports the subpackage that shares `name`, which used to bind
    # the module over the lazy export (TypeError: 'module' object is not callable)
    code = (f"import types\nfrom delaykit import {first}, {name}\nimport delaykit\n"
            f"assert callable({name}) and not isinstance({name}, types.ModuleType), {name}\n"
            f"assert delaykit.{name} is {name}\n"
            f"from delaykit.{name} import {'identification' if name == 'identify' else 'simulation'} as sub\n"
            f"assert delaykit.{name} is sub.{name}\n"
            f"print({name}.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().startswith(f"delaykit.{name}.")


def test_shared_names_are_every_exported_name_with_a_subpackage() -> None:
    import delaykit

    assert set(delaykit._SHARED) == {"identify", "simulate"}


def test_shared_name_can_be_monkeypatched(monkeypatch: pytest.MonkeyPatch) -> None:
    import delaykit

    original = delaykit.identify
    monkeypatch.setattr(delaykit, "identify", len)
    assert delaykit.identify is len
    monkeypatch.undo()
    assert delaykit.identify is original
