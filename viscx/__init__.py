"""viscx: the visibility complex of polygonal scenes.

The library is usable on its own; the ``viscx`` command (``viscx.cli``) is a thin
layer over it. In a notebook (:mod:`viscx.api`):

    >>> import viscx
    >>> cx = viscx.build("sample_scenes/cornell_box.obj")      # doctest: +SKIP
    >>> cx.shadows([278, 540, 280]).faces[0].area()             # doctest: +SKIP
    >>> cx.save("cornell.h5")                                   # doctest: +SKIP
    >>> cx = viscx.open("cornell.h5")                           # doctest: +SKIP
"""

__version__ = "0.1.0"

from viscx.errors import ViscxError  # noqa: E402

__all__ = ["Complex", "ViscxError", "__version__", "build", "load_scene", "open"]

# the public API, imported on first use so that `import viscx` (and `viscx --help`) stays light
_API = {"Complex": "viscx.api", "build": "viscx.api", "open": "viscx.api", "load_scene": "viscx.scene"}


def __getattr__(name):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'viscx' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_API))
