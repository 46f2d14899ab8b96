# The two set-up commands of the README: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
OUT    := out
# the Cornell box's classic camera, one exposure for every image so they compare
VIEW   := --camera 278,273,-800 --look-at 278,273,0 --fov 39.3 --size 512 512 --light-group light --exposure 6

.PHONY: demo test venv bench clean golden images

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Re-install when the package metadata changes.
# (the dask extra: the tests of `viscx build --scheduler`; about 6 CPU s more to install)
$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test,plot,dask]'
	touch $@

# Compile and cache the numba kernels (about a minute of CPU, once) so that the first build is
# as fast as the next; again after an install or a change of viscx's sources (numba's cache is
# keyed on them), not on every `make test` (with every kernel cached it still takes 3 s).
# The bytecode cache is kept where PYTHONDONTWRITEBYTECODE is set (see `test`).
SOURCES := $(shell find viscx -name '*.py')
$(VENV)/.warm: $(VENV)/.installed $(SOURCES)
	env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m viscx.warmup
	touch $@

venv: $(VENV)/.warm

demo: venv
	mkdir -p $(OUT)
	$(BIN)/viscx build sample_scenes/cornell_box.obj -o $(OUT)/cornell_box.h5
	$(BIN)/viscx info $(OUT)/cornell_box.h5
	$(BIN)/viscx query shadows $(OUT)/cornell_box.h5 --light 278,540,280 -o $(OUT)/cornell_shadows.ply
	$(BIN)/viscx render $(OUT)/cornell_box.h5 $(VIEW) -o $(OUT)/cornell_exact.png
	$(BIN)/viscx render $(OUT)/cornell_box.h5 $(VIEW) --samples 500 --show-regions -o $(OUT)/cornell_sparse500.png
	$(BIN)/viscx render $(OUT)/cornell_box.h5 $(VIEW) --reference 16 -o $(OUT)/cornell_mc16.png

# The README's pictures are the demo's: refresh them after a change of output.
images: demo
	cp $(OUT)/cornell_exact.png $(OUT)/cornell_sparse500.png $(OUT)/cornell_mc16.png docs/images/

# `venv` warms the kernels up first after a change of source: they are compiled once, not inside
# a test (the workers then only read numba's cache); JOBS pytest-xdist workers, each given whole files
# in the order tests/conftest.py sorts them, longest first (pytest-xdist would otherwise sort
# the files by their number of tests and hand a long file of one test out last)
# (the tests keep Python's bytecode cache even where PYTHONDONTWRITEBYTECODE is set: without it
# each worker and each of the tests' subprocesses compiles viscx and the tests from source again,
# about 15 s of the suite's wall on 2 cores)
# (PYTEST_ARGS: more pytest options, e.g. `make test PYTEST_ARGS=--durations=50`)
JOBS ?= 2
PYTEST_ARGS ?=
test: venv
	env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest -q -n $(JOBS) --dist loadscope --no-loadscope-reorder $(PYTEST_ARGS)

# Rebuild the golden files that tests/test_golden.py diffs against; run it only
# when a change of output is intended, and commit the result.
golden: venv
	$(BIN)/viscx -q build sample_scenes/two_triangles.obj -o tests/golden/two_triangles.h5
	$(BIN)/viscx -q build sample_scenes/tetrahedra.obj -o tests/golden/tetrahedra.h5
	$(BIN)/viscx -q build sample_scenes/boxes_on_floor.obj -o tests/golden/boxes_on_floor.h5
	$(BIN)/viscx -q build sample_scenes/cornell_box.obj -o tests/golden/cornell_box.h5
	$(BIN)/viscx -q build sample_scenes/room_with_door.obj -o tests/golden/room_with_door.h5
	$(BIN)/viscx -q build sample_scenes/occluder_over_plane.ply -o tests/golden/occluder_over_plane.h5

bench: venv
	$(BIN)/python benchmarks/run.py --quick

clean:
	rm -rf $(OUT) .pytest_cache
