"""V1 and V2 built streamed into a viscx file from the V0 of another (``viscx build --levels
0``), each stage's peak resident memory on its own: what the streamed ``viscx build`` holds
after V0, measured stage by stage on the large cities.

    python benchmarks/streamed_stages.py v0.h5 out.h5      # prints one JSON line per stage
    python benchmarks/streamed_stages.py v0.h5 out.h5 --scheduler local --workers 2
    python benchmarks/streamed_stages.py v0.h5 v1.h5 --levels 1   # V0 and V1 only, then
    python benchmarks/streamed_stages.py v1.h5 out.h5             # V2 alone from that V1

The output is the file ``viscx build`` writes (V0 copied, V1 by ``stream_arcs``' steps, V2
by ``stream_two_cells``; an input that holds V1 has V0 and V1 copied and only V2 built, so
that V2 can be measured and rerun alone): ``viscx diff --rtol 0 --atol 0`` against a whole build of the same
scene shows they agree. Stage peaks are the process's high-water mark (``VmHWM``), reset at
each stage's start (``/proc/self/clear_refs``, Linux), so each is that stage's own peak with
what the process already held. With ``--scheduler``, the chunks of V1 and V2 run as dask
tasks (:mod:`viscx.distributed`) and the last line gives each worker's peak.
"""

import argparse
import json
import time
from pathlib import Path


def _hwm_gb():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024 / 1e9
    return float("nan")


def _reset_hwm():
    Path("/proc/self/clear_refs").write_text("5")


class _Stage:
    """``with _Stage(name):`` prints ``{"stage", "wall", "cpu", "peak_gb"}`` at the end."""

    def __init__(self, name):
        self.name = name

    def __enter__(self):
        from viscx.memory import release_free_memory

        release_free_memory()
        _reset_hwm()
        self.wall, self.cpu = time.perf_counter(), time.process_time()

    def __exit__(self, *exc):
        print(json.dumps({"stage": self.name, "wall": round(time.perf_counter() - self.wall, 1),
                          "cpu": round(time.process_time() - self.cpu, 1), "peak_gb": round(_hwm_gb(), 3)}),
              flush=True)


def main(v0_path, out_path, scheduler=None, workers=None, levels=2, planar_alone=False):
    import h5py

    from viscx.distributed import runner as make_runner
    from viscx.formats.hdf5 import complex_writer, stored_nodes
    from viscx.pipeline import level_writers, open_complex, stream_arcs, stream_two_cells
    from viscx.skeleton.arcs.events import planar_events
    from viscx.skeleton.chunks import stored_v2_arcs

    with _Stage("read V0"):
        cx = open_complex(v0_path)
        scene = cx.scene
        options = {**cx.options, "levels": levels}
        has_v1 = "V1" in cx.stored
    names = ["V0", "V1", "V2"][: levels + 1]
    runner = make_runner(scheduler, workers)
    with complex_writer(out_path, scene, names, options) as f:
        with _Stage("copy V0" + (" and V1" if has_v1 else "")):
            if has_v1:  # the groups copied as stored (HDF5 copies dataset by dataset, chunk by chunk)
                with h5py.File(v0_path, "r") as source:
                    for name in ("V0", "V1"):
                        source.copy(source[name], f, name)
            else:
                level_writers({"V0": cx.nodes})["V0"](f.create_group("V0", track_order=True))
            del cx
        if not has_v1:
            if planar_alone:
                with _Stage("V1 planar events (alone)"):
                    planar_events(scene)
            # as viscx build: the nodes read back from the file
            stream_arcs(scene, stored_nodes(f["V0"]), f.create_group("V1", track_order=True), runner,
                        step=lambda name: _Stage("V1 " + name))
        if levels >= 2:
            with _Stage("V2"):
                stream_two_cells(scene, stored_v2_arcs(f["V1"]), f.create_group("V2", track_order=True), runner)
        print(json.dumps({"worker_peaks_gb": {k: round(v, 3) for k, v in runner.peaks().items()}}), flush=True)
    runner.close()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("v0")
    parser.add_argument("output")
    parser.add_argument("--scheduler", default=None, help="'local' or a dask scheduler's address")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--levels", type=int, default=2, choices=[1, 2], help="the last level written (1: V0 and V1)")
    parser.add_argument("--planar-alone", action="store_true", help="also time V1's planar events on their own first")
    args = parser.parse_args()
    main(args.v0, args.output, args.scheduler, args.workers, args.levels, args.planar_alone)
