"""The book's Python page (docs/src/python.md) against the package: every name of the API is on
the page and has a docstring, every public method and property of its classes has one, and every
``st.<name>`` the page shows exists — so the page cannot fall behind the docstrings unnoticed."""

import inspect
import re
from pathlib import Path

import shear_twin as st

PAGE = Path(__file__).resolve().parents[2] / "docs" / "src" / "python.md"


def test_every_name_of_the_api_is_on_the_page_with_a_docstring():
    page = PAGE.read_text()
    absent = [n for n in st.__all__ if not re.search(rf"\b{re.escape(n)}\b", page)]
    assert not absent, f"not on {PAGE.name}: {absent}"
    undocumented = [n for n in st.__all__ if not (getattr(st, n).__doc__ or "").strip()]
    assert not undocumented, undocumented


def test_every_public_method_of_the_api_has_a_docstring():
    missing = []
    for name in st.__all__:
        cls = getattr(st, name)
        if not inspect.isclass(cls) or issubclass(cls, BaseException):
            continue
        for member in (m for m in dir(cls) if not m.startswith("_")):
            if not (getattr(cls, member).__doc__ or "").strip():
                missing.append(f"{name}.{member}")
    assert not missing, missing


def test_every_call_the_page_shows_exists():
    shown = set(re.findall(r"\bst\.([A-Za-z_]\w*)", PAGE.read_text()))
    assert shown, "the page shows calls as st.<name>"
    assert not [n for n in shown if not hasattr(st, n)], sorted(n for n in shown if not hasattr(st, n))
