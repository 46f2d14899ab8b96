"""File size and write time of each ``viscx build --compression`` coder on the cities.

    python benchmarks/compression.py                 # 300 and 1000 polygons, every level
    python benchmarks/compression.py --sizes 300     # one city

Each city (``scenes.random_boxes``) is built once, level by level, then written with
every coder twice (none, gzip, lzf); CPU seconds (``time.process_time``: all threads) so
that a shared machine's load does not enter. Prints one JSON line per city and writes
``benchmarks/compression_results.json``. The 1000-polygon city needs about 3 GB; run it
under ``prlimit --as=7000000000`` on a shared machine.
"""

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from scenes import random_boxes  # noqa: E402

from viscx.formats.hdf5 import COMPRESSIONS, write_complex  # noqa: E402
from viscx.pipeline import LEVELS, level_writers  # noqa: E402


def measure(size, levels=2, repeats=2):
    cpu = time.process_time
    scene = random_boxes(size, seed=0)
    stages, built = {}, {}
    for name, builder in LEVELS[: levels + 1]:
        c0 = cpu()
        built[name] = builder(scene, built, True)
        stages[name] = cpu() - c0
    row = {"polygons": int(scene.n_faces), "levels": levels, "stage_cpu": stages, "build_cpu": sum(stages.values()),
           "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9, "writes": {}}
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(repeats):
            for coder in COMPRESSIONS:
                out = Path(folder) / f"{coder}.h5"
                c0 = cpu()
                write_complex(out, scene, levels=level_writers(built), options={"levels": levels}, compression=coder)
                row["writes"].setdefault(coder, []).append({"cpu": cpu() - c0, "bytes": os.path.getsize(out)})
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[300, 1000])
    parser.add_argument("--levels", type=int, default=2)
    parser.add_argument("--out", default=str(HERE / "compression_results.json"))
    args = parser.parse_args()
    rows = []
    for size in args.sizes:
        rows.append(measure(size, args.levels))
        print(json.dumps(rows[-1]), flush=True)
    Path(args.out).write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
