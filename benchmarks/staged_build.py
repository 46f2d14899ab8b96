"""The streamed full build split into stages, each its own process and file, so that a
later stage can be rerun alone from the earlier one's output (a long build, e.g. the whole
npm bunny, measured stage by stage: CPU, wall and peak resident memory of each process).

    viscx build scene.obj --levels 0 -o v0.h5                   # V0
    python benchmarks/staged_build.py v1 v0.h5 v1.h5            # V0 copied, V1 streamed
    python benchmarks/staged_build.py v2 v1.h5 full.h5          # V0 and V1 copied, V2 streamed

Run each under ``/usr/bin/time -v`` for the process's figures. The V1 file is a viscx file
of levels V0 and V1 (option ``levels`` 1), the last one the file ``viscx build`` writes
(``viscx diff --rtol 0 --atol 0`` shows it: the levels are copied dataset for dataset and
built by the streamed build's own steps, :func:`viscx.pipeline.stream_arcs` and
:func:`viscx.pipeline.stream_two_cells`). Prints one JSON line: the stage's wall and CPU
seconds, the process's peak (``VmHWM``) and the counts written.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import h5py

sys.path.insert(0, str(Path(__file__).resolve().parent))

from streamed_stages import _hwm_gb  # noqa: E402


def main(stage, source, output, scheduler=None, workers=None):
    from viscx.distributed import runner as make_runner
    from viscx.formats.hdf5 import complex_writer, stored_nodes
    from viscx.pipeline import open_complex, stream_arcs, stream_two_cells
    from viscx.skeleton.chunks import stored_v2_arcs

    cx = open_complex(source)
    levels = {"v1": 1, "v2": 2}[stage]
    names = ["V0", "V1", "V2"][: levels + 1]
    timings = {}
    wall, cpu = time.perf_counter(), time.process_time()
    runner = make_runner(scheduler, workers)
    try:
        with (complex_writer(output, cx.scene, names, {**cx.options, "levels": levels}, timings) as f,
              h5py.File(source, "r") as src):
            for name in names[:-1]:
                src.copy(src[name], f, name=name)
            group = f.create_group(names[-1], track_order=True)
            if stage == "v1":
                counts = {"arcs": stream_arcs(cx.scene, stored_nodes(f["V0"]), group, runner, quiet=False)}
            else:
                counts = stream_two_cells(cx.scene, stored_v2_arcs(f["V1"]), group, runner, timings, quiet=False)
        peaks = runner.peaks()
    finally:
        runner.close()
    print(json.dumps({"stage": stage, "wall": round(time.perf_counter() - wall, 1),
                      "cpu": round(time.process_time() - cpu, 1), "peak_gb": round(_hwm_gb(), 3), **counts,
                      **({"worker_peaks_gb": peaks} if peaks else {})}), flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("stage", choices=("v1", "v2"))
    parser.add_argument("source", help="the V0 file (stage v1) or the V1 file (stage v2)")
    parser.add_argument("output")
    parser.add_argument("--scheduler", default=None, help="'local' or a dask scheduler's address")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    main(args.stage, args.source, args.output, args.scheduler, args.workers)
