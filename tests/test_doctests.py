"""The docstring examples of every module run and print what they show."""

import doctest
import importlib
import pkgutil

import pytest

import voxgi

MODULES = sorted(
    m.name for m in pkgutil.walk_packages(voxgi.__path__, "voxgi.") if m.name != "voxgi._core"
)


@pytest.mark.parametrize("name", ["voxgi", *MODULES])
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
