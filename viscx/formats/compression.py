"""The coders of the viscx container's large datasets, without h5py: the command line lists
them (``viscx build --compression``) before it knows whether it will write a file."""

#: The coders of ``viscx build --compression`` for the large datasets: (filter, level).
#: Integer arrays are byte-shuffled first (the high bytes of ids, all zero, line up into
#: runs); float arrays are not, as their repeats are whole values (a vertex's coordinates
#: in every generator point on it) that shuffling would cut apart. Measured on the
#: 301-polygon city (98 MB raw): gzip level 1 3.0x smaller for 1.3 s of CPU to write
#: (the build: 30 s), lzf 2.4x for 0.8 s; shuffling the floats too: 2.35x and 1.9x.
#: gzip is the default: any HDF5 library reads it (lzf needs h5py's own plugin).
COMPRESSIONS = {"none": None, "gzip": ("gzip", 1), "lzf": ("lzf", None)}
DEFAULT_COMPRESSION = "gzip"
