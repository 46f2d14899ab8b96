"""Fuzz: mutated viscx files (dtypes flipped, datasets dropped, rows shuffled or cut, NaNs
and wild ids, attributes damaged, files truncated) given to the CLI. Every run must end with
exit 0 or 2 (one line on stderr), never a signal, never exit 1 (an internal error), and never
leave an output or temporary file behind.

Hypothesis draws the seeds of batches of mutations; each batch runs in subprocesses
(tests/fuzz_worker.py, the CLI in-process there), so that a crash kills the worker and not
pytest, and names the mutation that caused it. Default suite: one batch of 100 mutations of
the two-triangle golden file in one worker, every kind of mutation 12 or 13 times (``make
test``'s other pytest worker has the second core; 6 s); ``-m slow``: 10^4 over three golden
files, two workers.
"""

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

HERE = Path(__file__).resolve().parent
OPS = ["drop", "dtype", "shuffle", "nan", "values", "rows", "truncate", "attribute"]



def mutations_of(seed, count):
    """``count`` mutations drawn from ``seed``: every kind in turn, a random dataset (or
    attribute) and a random seed for the change itself."""
    rng = np.random.default_rng(seed)
    return [{"op": OPS[(k + seed) % len(OPS)], "target": int(rng.integers(10**6)), "seed": int(rng.integers(2**32))}
            for k in range(count)]


def run_batch(golden, mutations, tmp_path, workers=2):
    """Run one batch in ``workers`` concurrent worker processes (the machine's two cores);
    returns the failures as readable lines."""
    share = -(-len(mutations) // workers)
    parts = [mutations[k:k + share] for k in range(0, len(mutations), share)]
    processes = []
    for k, part in enumerate(parts):
        batch = tmp_path / f"batch{k}.json"
        batch.write_text(json.dumps({"golden": golden, "mutations": part}))
        processes.append(subprocess.Popen([sys.executable, str(HERE / "fuzz_worker.py"), str(batch)],
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    failures = []
    for part, process in zip(parts, processes):
        out, err = process.communicate(timeout=3600)
        failures += _failures(part, process.returncode, out, err)
    return failures


def _failures(mutations, returncode, out, err):
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    failures = []
    if returncode != 0:
        started = [line["start"] for line in lines if "start" in line]
        last = mutations[started[-1]] if started else None
        name = signal.Signals(-returncode).name if returncode < 0 else returncode
        failures.append(f"worker ended by {name} on mutation {last}: {err[-2000:]}")
    for line in lines:
        for command, code, message, left in line.get("results", []):
            spec = mutations[line["i"]]
            if code not in (0, 2):
                failures.append(f"{spec} {command}: exit {code}: {message.strip()}")
            elif code == 2 and (message.count("\n") != 1 or "Traceback" in message):
                failures.append(f"{spec} {command}: not one line: {message!r}")
            if left:
                failures.append(f"{spec} {command}: left behind {left}")
    return failures


# no shrinking: a seed has no structure to shrink, and the failure names its mutation
SETTINGS = dict(deadline=None, derandomize=True, database=None, phases=[Phase.explicit, Phase.generate],
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@settings(max_examples=1, **SETTINGS)
@given(st.integers(0, 2**32 - 1))
def test_mutated_files_never_crash(tmp_path, seed):
    failures = run_batch("two_triangles.h5", mutations_of(seed, 100), tmp_path, workers=1)
    assert not failures, "\n".join(failures[:20])


@pytest.mark.slow
@pytest.mark.parametrize("golden, batches", [("two_triangles.h5", 20), ("tetrahedra.h5", 10), ("cornell_box.h5", 10)])
def test_mutated_files_never_crash_many(golden, batches, tmp_path):
    """10^4 mutations: 40 batches of 250 (20 of the two triangles, 10 each of the others)."""

    @settings(max_examples=batches, **SETTINGS)
    @given(st.integers(0, 2**32 - 1))
    def check(seed):
        failures = run_batch(golden, mutations_of(seed, 250), tmp_path)
        assert not failures, "\n".join(failures[:20])

    check()
