"""File formats: the only package that knows file layouts.

- :mod:`viscx.formats.obj`: the OBJ/MTL reader (groups and materials kept).
- :mod:`viscx.formats.hdf5`: the viscx container (one group per skeleton level).
- :mod:`viscx.formats.atomic`: write-to-temporary-then-rename for every output.
"""
