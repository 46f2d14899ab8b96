"""viscx: the visibility complex of polygonal scenes.

The library is usable on its own; the ``viscx`` command (``viscx.cli``) is a thin
layer over it.

    >>> import viscx
    >>> scene = viscx.load_scene("sample_scenes/cornell_box.obj")   # doctest: +SKIP
"""

__version__ = "0.1.0"

from viscx.errors import ViscxError  # noqa: E402

__all__ = ["ViscxError", "__version__", "load_scene"]


def load_scene(path, **options):
    """Load a scene file into a :class:`viscx.scene.Scene` (see there)."""
    from viscx.scene import load_scene as _load

    return _load(path, **options)
