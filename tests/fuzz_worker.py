"""Worker of the viscx-file fuzz test (tests/test_fuzz.py): applies each mutation of a batch
to a fresh copy of a golden file and runs viscx commands on it in this one process.

``python tests/fuzz_worker.py BATCH.json`` prints one JSON line per mutation,
``{"i": i, "results": [[command, exit code, stderr, files left], ...]}``, and
``{"start": i}`` before each, so that a worker killed by a signal names the mutation.
"""

import contextlib
import io
import json
import shutil
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

GOLDEN = Path(__file__).resolve().parent / "golden"
DTYPES = ["int8", "int32", "uint64", "float32", "float64", "bool", "str"]


def datasets(f):
    names = []  # HDF5's walk with its object types (h5py's visititems opens each object)
    h5py.h5o.visit(f.id, lambda name, info: names.append(name.decode()) if info.type == h5py.h5o.TYPE_DATASET else None,
                   info=True)
    return sorted(names)


def mutate(path, spec, rng):
    """Apply one mutation ``spec`` = ``{"op", "target", "seed"}`` to the viscx file ``path``."""
    op = spec["op"]
    if op == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: int(len(data) * rng.uniform(0.05, 0.99))])
        return
    with h5py.File(path, "r+") as f:
        if op == "attribute":
            groups = ["/"] + sorted(name for name in f if isinstance(f[name], h5py.Group))
            obj = f[groups[spec["target"] % len(groups)]]
            names = sorted(obj.attrs) or ["counts"]
            name = names[spec["target"] // len(groups) % len(names)]
            value = [np.nan, "text", -1, 1e308, "[" * 5000 + "]" * 5000, '{"a": 1.5}', '["scene", "V9"]',
                     '{"cells": "x"}', b"\xff\xfe", None][int(rng.integers(10))]
            if value is None:
                obj.attrs.pop(name, None)
            else:
                obj.attrs[name] = value
            return
        names = datasets(f)
        name = names[spec["target"] % len(names)]
        data = f[name][()]
        if op == "drop":
            del f[name]
            return
        if op == "dtype":
            to = DTYPES[int(rng.integers(len(DTYPES)))]
            if to == "str":
                del f[name]
                f.create_dataset(name, data=np.array(np.asarray(data).astype(str), dtype=object),
                                 dtype=h5py.string_dtype())
                return
            new = np.asarray(data).astype(to) if data.dtype.kind in "biuf" else np.zeros(data.shape, to)
        elif op == "shuffle":
            new = np.array(data)
            if new.ndim and len(new) > 1:
                new = new[rng.permutation(len(new))]
            elif new.size > 1:
                new = rng.permutation(new.ravel()).reshape(new.shape)
        elif op == "nan":
            new = np.array(data)
            if new.size and new.dtype.kind == "f":
                new.flat[int(rng.integers(new.size))] = [np.nan, np.inf, -np.inf, 1e300][int(rng.integers(4))]
            elif new.size and new.dtype.kind in "iu":
                new.flat[int(rng.integers(new.size))] = [-1, -2, 0, 2**31, 2**62, int(new.max()) + 1][int(rng.integers(6))] \
                    if new.dtype.itemsize == 8 else 0
            elif new.size and new.dtype.kind == "b":
                new = ~new
        elif op == "values":  # every value of the dataset replaced
            new = np.array(data)
            if new.dtype.kind in "iu" and new.size:
                new[...] = rng.integers(-2, max(3, 2 * int(new.max()) + 3), size=new.shape).astype(new.dtype)
            elif new.dtype.kind == "f":
                new = rng.normal(size=new.shape) * 10.0 ** rng.integers(-3, 4)
        elif op == "rows":  # one row fewer or more
            new = np.array(data)
            if new.ndim:
                new = new[:-1] if len(new) and rng.integers(2) else np.concatenate([new, new[:1]])
        else:
            raise ValueError(op)
        del f[name]
        f.create_dataset(name, data=new)


def commands(path, out, i):
    """The commands run on mutation i: a point query (the scene into the ray caster and the
    V-cell kernels) or the discontinuity mesh (V1 into its kernels) in turn, and every 20th
    mutation also ``info`` (V0's sites) and ``diff`` (every dataset and attribute)."""
    p = str(path)
    chosen = [["query", "visible", p, "--from", "0.2,0.3,0.9", "-o", str(out / "view.json")],
              ["query", "discontinuities", p, "--light-face", "0", "-o", str(out / "mesh.json")]][i % 2:][:1]
    if i % 20 == 0:
        chosen += [["info", p], ["diff", p, p]]
    return chosen


def run(argv):
    from viscx.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main(["--quiet", *argv])
            code = 0
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


def main(batch_path):
    batch = json.loads(Path(batch_path).read_text())
    golden = GOLDEN / batch["golden"]
    for i, spec in enumerate(batch["mutations"]):
        print(json.dumps({"start": i}), flush=True)
        rng = np.random.default_rng(spec["seed"])
        with tempfile.TemporaryDirectory() as folder:
            folder = Path(folder)
            path = folder / "input.h5"
            shutil.copyfile(golden, path)
            mutate(path, spec, rng)
            out = folder / "out"
            out.mkdir()
            results = []
            for argv in commands(path, out, i):
                code, err = run(argv)
                left = sorted(p.name for p in out.iterdir())
                if code == 0:  # a success writes its output; clear it for the next command
                    for p in out.iterdir():
                        p.unlink()
                    left = []
                results.append([argv[0] if argv[0] != "query" else argv[1], code, err, left])
        print(json.dumps({"i": i, "results": results}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
