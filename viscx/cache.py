"""A declared cache of derived data on a record (:class:`Cached`)."""


class Cached:
    """Mixin for dataclasses with a ``cache : dict`` field (declared with
    ``field(default_factory=dict, init=False, repr=False, compare=False)``, so that
    :func:`dataclasses.replace` gives the new record an empty cache): data derived from
    the record, computed once on first use."""

    def cached(self, name, build):
        """``build(self)``, computed on the first call for ``name`` and kept in ``cache``.

        Parameters
        ----------
        name : str
            The key: the name of the public function returning the data.
        build : callable
            record -> the data; must depend on nothing but the record (and what the
            record's class docstring says its cache may depend on).
        """
        if name not in self.cache:
            self.cache[name] = build(self)
        return self.cache[name]
