"""Images of a scene lit by an area light: the camera's primary hits (:mod:`.camera`), exact
direct illumination region by region (:mod:`.direct`), its sparse reconstruction
(:mod:`.sparse`), the Monte Carlo reference (:mod:`.montecarlo`) and the render job
(:mod:`.image`)."""

# (viscx.flatland.plot still imports pyplot from here: the lead moves it to viscx.plot)
from viscx.plot import pyplot  # noqa: F401
