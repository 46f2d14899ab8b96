"""Pictures of the 3-D complex (matplotlib, the optional ``plot`` extra, imported lazily)."""

from viscx.errors import ViscxError


def pyplot():
    """matplotlib.pyplot on the Agg backend, or a one-line error naming the extra."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise ViscxError("plotting needs matplotlib: pip install 'viscx[plot]'") from None
    return plt
