# Quick start:  `make demo`  (sets up .venv, runs the main example, writes its plots)
#               `make fig2`  (the paper's Fig. 2: partial slip of a tilted ellipsoid, out/fig2)
#               `make test`  (sets up .venv, runs ruff and the whole test suite)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: demo fig2 test test-fast lint bench clean venv

$(BIN)/activate:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(VENV)/.installed-test: pyproject.toml | $(BIN)/activate
	$(BIN)/pip install --quiet -e ".[test]"
	touch $@

$(VENV)/.installed-bench: pyproject.toml | $(BIN)/activate
	@# aspher builds from source and needs Eigen >= 3.4 (it cannot download it here)
	@test -f /usr/share/eigen3/cmake/Eigen3Config.cmake || \
		(apt-get update -qq && apt-get install -y -qq libeigen3-dev)
	$(BIN)/pip install --quiet -e ".[test,bench]"
	touch $@

venv: $(VENV)/.installed-test

demo: $(VENV)/.installed-test
	$(BIN)/python examples/hertz_demo.py --out $(OUT)

fig2: $(VENV)/.installed-test
	$(BIN)/python examples/fig2_partial_slip.py --out $(OUT)/fig2

test: $(VENV)/.installed-test
	$(BIN)/ruff check src tests benchmarks examples
	$(BIN)/python -m pytest

test-fast: $(VENV)/.installed-test
	$(BIN)/python -m pytest -m "not slow" -x -q

lint: $(VENV)/.installed-test
	$(BIN)/ruff check src tests benchmarks examples

bench: $(VENV)/.installed-bench
	$(BIN)/python benchmarks/normal_hertz.py

bench-tangential: $(VENV)/.installed-bench
	$(BIN)/python benchmarks/tangential_cattaneo.py --md benchmarks/results/tangential_cattaneo.md

clean:
	rm -rf $(VENV) $(OUT) build src/*.egg-info .pytest_cache
