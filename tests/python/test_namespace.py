"""The package's namespace is its API: every public name of ``shear_twin`` is in ``__all__`` (or
is one of its submodules, such as ``shear_twin.fleet``), and every name in ``__all__`` exists —
no ``json``, ``os`` or typing helpers leaking out of the implementation."""

import types

import shear_twin as st


def test_every_public_name_is_the_api():
    public = {n for n in dir(st) if not n.startswith("_")}
    submodules = {n for n in public if isinstance(getattr(st, n), types.ModuleType)
                  and getattr(st, n).__name__.startswith("shear_twin.")}
    assert public - submodules == set(st.__all__), sorted(public - submodules ^ set(st.__all__))
    for leaked in ("json", "os", "Any", "Callable", "Mapping", "Sequence", "TYPE_CHECKING", "annotations"):
        assert not hasattr(st, leaked), leaked
