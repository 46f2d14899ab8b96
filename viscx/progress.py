"""Progress bars for long stages (tqdm on stderr), switched off by ``quiet``."""

from tqdm import tqdm


def bar(total=None, desc=None, quiet=False, unit="it"):
    """A tqdm bar for a stage; disabled when ``quiet`` or when stderr is not a terminal."""
    return tqdm(total=total, desc=desc, unit=unit, disable=True if quiet else None, leave=False, dynamic_ncols=True)
