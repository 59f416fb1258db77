# Quick start:  `make demo`  (sets up .venv, runs the paper's Fig. 3 particle simulation, plots in out/fig3)
#               `make test`  (sets up .venv, runs ruff, builds the docs strictly, runs the whole test suite)
# More:         `make fig2` `make fig4` `make fig5` (the paper's other figures), `make hertz`,
#               `make layer` (30 potatoes between the plates), `make layer-hertz`,
#               `make shear` (a periodic layer of 8 potatoes compressed, then slid 1.5 mm),
#               `make sweep` (a 20-case sweep on a local dask cluster),
#               `make bench`, `make bench-tangential`, `make bench-simulation`, `make bench-sweep`,
#               `make bench-layer`,
#               `make mutation` (mutmut over the particle physics),
#               `make mutation-network` (mutmut over the dense network's model and solver),
#               `make docs` (the documentation site into site/; `make test` builds it too)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: demo hertz fig2 fig3 fig4 fig5 layer layer-hertz shear sweep test test-all test-fast lint docs bench \
	bench-tangential bench-simulation bench-sweep bench-layer mutation mutation-network clean venv

$(BIN)/activate:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

# the test environment also builds the documentation (`make test` runs `mkdocs build --strict`)
$(VENV)/.installed-test: pyproject.toml | $(BIN)/activate
	$(BIN)/pip install --quiet -e ".[test,docs]"
	touch $@

$(VENV)/.installed-mutation: pyproject.toml | $(BIN)/activate
	$(BIN)/pip install --quiet -e ".[test,docs,mutation]"
	touch $@

$(VENV)/.installed-bench: pyproject.toml | $(BIN)/activate
	@# aspher builds from source and needs Eigen >= 3.4 (it cannot download it here)
	@test -f /usr/share/eigen3/cmake/Eigen3Config.cmake || \
		(apt-get update -qq && apt-get install -y -qq libeigen3-dev)
	$(BIN)/pip install --quiet -e ".[test,docs,bench]"
	touch $@

venv: $(VENV)/.installed-test

demo: fig3

hertz: $(VENV)/.installed-test
	$(BIN)/python examples/hertz_demo.py --out $(OUT)

fig3 fig4 fig5: $(VENV)/.installed-test
	$(BIN)/python examples/paper_figures.py --figure $(subst fig,,$@) --out $(OUT)/$@

fig2: $(VENV)/.installed-test
	$(BIN)/python examples/fig2_partial_slip.py --out $(OUT)/fig2

layer: $(VENV)/.installed-test
	$(BIN)/thirdbody run src/thirdbody/examples/layer_polydisperse.toml -o $(OUT)/layer
	$(BIN)/thirdbody export-vtk $(OUT)/layer/results.nc $(OUT)/layer/vtk

# a shear test (docs/guide/sliding.md): results.nc and the figures (shear.png: mu_eff, dilatancy
# and the energy against the sliding distance; layer_top_view.png) in out/shear
shear: $(VENV)/.installed-test
	$(BIN)/thirdbody run src/thirdbody/examples/shear_layer.toml -o $(OUT)/shear

layer-hertz: $(VENV)/.installed-test
	$(BIN)/python examples/layer_hertz_check.py --out $(OUT)/layer_hertz

sweep: $(VENV)/.installed-test
	$(BIN)/thirdbody sweep src/thirdbody/examples/sweep_fig4.toml -o $(OUT)/sweep_fig4

# CI: ruff, the docs built strictly, every test not marked slow (under 10 minutes on 2 cores)
test: $(VENV)/.installed-test
	$(BIN)/ruff check src tests benchmarks examples docs/hooks
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet --site-dir site
	$(BIN)/python -m pytest -n 2 --dist loadfile -m "not slow"

# everything: make test, then the slow cases (kills and resumes, whole paper runs, sweeps'
# interrupts, the README's and the pages' heavier snippets); before merging a solver change
test-all: test
	$(BIN)/python -m pytest -n 2 --dist loadfile -m slow

test-fast: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n 2 --dist loadfile -m "not slow" -x -q

lint: $(VENV)/.installed-test
	$(BIN)/ruff check src tests benchmarks examples docs/hooks

# the documentation site (mkdocs-material + mkdocstrings) into site/; --strict: a broken link, a
# missing page or an API reference that does not resolve fails the build
docs: $(VENV)/.installed-test
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

bench: $(VENV)/.installed-bench
	$(BIN)/python benchmarks/normal_contact.py --json benchmarks/results/normal_contact.json --md benchmarks/results/normal_contact.md

bench-tangential: $(VENV)/.installed-bench
	$(BIN)/python benchmarks/tangential_cattaneo.py --md benchmarks/results/tangential_cattaneo.md

bench-simulation: $(VENV)/.installed-test
	$(BIN)/python benchmarks/simulation_fig3.py

bench-layer: $(VENV)/.installed-test
	$(BIN)/python benchmarks/layer.py --md benchmarks/results/layer.md

bench-sweep: $(VENV)/.installed-test
	$(BIN)/python benchmarks/sweep_throughput.py --md benchmarks/results/sweep_throughput.md

# mutation testing of the particle physics ([tool.mutmut] in pyproject.toml); hours on 2 cores
mutation: $(VENV)/.installed-mutation
	$(BIN)/mutmut run --max-children 2 || true
	$(BIN)/mutmut results

# mutation testing of the dense network (network/stiffness.py, network/cluster.py) in a scratch
# copy whose [tool.mutmut] is tests/mutmut-network.toml (docs/development/mutation.md);
# MUTANTS picks some by name (`make mutation-network MUTANTS='thirdbody.network.stiffness*'`),
# MUTATION_TESTS replaces the test files it runs, MUTATION_JOBS is the number of workers
MUTATION_NETWORK ?= build/mutation-network
MUTATION_JOBS ?= 1
MUTATION_TESTS ?=
MUTANTS ?=
mutation-network: $(VENV)/.installed-mutation
	mkdir -p $(MUTATION_NETWORK)
	rm -rf $(MUTATION_NETWORK)/src $(MUTATION_NETWORK)/tests $(MUTATION_NETWORK)/examples
	cp -rp src tests examples $(MUTATION_NETWORK)/
	cat tests/_mutmut_network_conftest.py >> $(MUTATION_NETWORK)/tests/conftest.py
	$(BIN)/python -c "import re, sys; text = open('pyproject.toml').read(); \
		section = open('tests/mutmut-network.toml').read().strip(); \
		tests = ', '.join(repr(t) for t in sys.argv[2:]); \
		section = re.sub(r'(?ms)^pytest_add_cli_args_test_selection = .*?\]', \
		lambda m: 'pytest_add_cli_args_test_selection = [' + tests + ']', section) \
		if tests else section; \
		open(sys.argv[1], 'w').write(re.sub(r'\[tool\.mutmut\].*?(?=\n\[|\Z)', \
		lambda m: section, text, flags=re.S))" $(MUTATION_NETWORK)/pyproject.toml \
		$(MUTATION_TESTS)
	cd $(MUTATION_NETWORK) && $(abspath $(BIN))/mutmut run --max-children $(MUTATION_JOBS) \
		$(MUTANTS) || true
	cd $(MUTATION_NETWORK) && $(abspath $(BIN))/mutmut results

clean:
	rm -rf $(VENV) $(OUT) build site src/*.egg-info .pytest_cache mutants
