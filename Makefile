# The two set-up commands of the README: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
OUT    := out

.PHONY: demo test venv bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Re-install when the package metadata changes.
$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test,plot]'
	touch $@

venv: $(VENV)/.installed

demo: venv
	mkdir -p $(OUT)
	$(BIN)/viscx build sample_scenes/cornell_box.obj -o $(OUT)/cornell_box.h5
	$(BIN)/viscx info $(OUT)/cornell_box.h5

test: venv
	$(BIN)/python -m pytest -q

bench: venv
	$(BIN)/python benchmarks/run.py --quick

clean:
	rm -rf $(OUT) .pytest_cache
