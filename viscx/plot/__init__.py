"""Plots of the 3-D complex's cells (matplotlib, the optional ``plot`` extra, imported
lazily): a vertex's V-cells on its direction sphere (:mod:`.vcell_sphere`) and an edge
pair's EE-cells in its square (:mod:`.eecell_square`)."""

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
