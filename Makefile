# Two entry points for a fresh clone (see README): `make demo` and `make test`.
# Each creates .venv on first use and (re)installs when pyproject.toml changes.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test test-fast bench embedded docs lint clean

$(VENV)/.installed-%: pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[$*]'
	@touch $@

## demo: run the paper's robot-arm case study into robot-arm-out/
demo: $(VENV)/.installed-plot
	$(BIN)/etobs demo robot-arm --out robot-arm-out

## lint: ruff (lint and format) and mypy (strict where pyproject.toml says)
lint: $(VENV)/.installed-test
	$(BIN)/ruff check src tests benchmarks examples docs/conf.py docs/gallery_scraper.py conftest.py
	$(BIN)/ruff format --check src tests benchmarks examples docs/conf.py docs/gallery_scraper.py conftest.py
	$(BIN)/mypy

## test: lint, the whole test suite (slow tests included, one process per core, each test
## file in one process: pytest-xdist), the benchmarks in quick mode
test: lint
	$(BIN)/python -m pytest -n auto --dist loadfile --doctest-modules src tests
	$(BIN)/python benchmarks/bench_robot_arm.py --quick
	$(BIN)/python benchmarks/bench_scaling.py --quick
	$(BIN)/python benchmarks/bench_accuracy.py --quick
	$(BIN)/python benchmarks/bench_user_model.py --quick
	$(BIN)/python benchmarks/bench_extensions.py --quick
	$(BIN)/python benchmarks/bench_model_cost.py --quick
	$(BIN)/python benchmarks/bench_tune.py --quick
	$(BIN)/python benchmarks/bench_vecmath.py --quick
	$(BIN)/python benchmarks/bench_lanes.py --quick
	$(BIN)/python benchmarks/bench_c_node.py --quick

## test-fast: the test suite without the tests marked slow
test-fast: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n auto --dist loadfile -m "not slow" src tests --doctest-modules

## bench: the benchmarks at full size
bench: $(VENV)/.installed-test
	$(BIN)/python benchmarks/bench_robot_arm.py
	$(BIN)/python benchmarks/bench_scaling.py
	$(BIN)/python benchmarks/bench_accuracy.py --runs 30 --rtol 1e-10 1e-9 1e-8
	$(BIN)/python benchmarks/bench_user_model.py
	$(BIN)/python benchmarks/bench_extensions.py
	$(BIN)/python benchmarks/bench_model_cost.py
	$(BIN)/python benchmarks/bench_tune.py
	$(BIN)/python benchmarks/bench_vecmath.py
	$(BIN)/python benchmarks/bench_lanes.py --base 752f71e
	$(BIN)/python benchmarks/bench_c_node.py

## embedded: the generated C node on a Cortex-M4F under QEMU (mps2-an386): its tests and its
## instruction count. Installs Debian's gcc-arm-none-eabi, libnewlib-arm-none-eabi and
## qemu-system-arm when missing (apt-get, as root: about 80 s and 2.3 GB). `make test` runs the
## same vectors on the host's gcc, and these tests too where the tools are installed.
embedded: $(VENV)/.installed-test
	@command -v arm-none-eabi-gcc >/dev/null && command -v qemu-system-arm >/dev/null || \
		(apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
		 gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm)
	$(BIN)/python -m pytest -m embedded -s tests/codegen
	$(BIN)/python benchmarks/bench_c_node.py

## docs: the documentation site into docs/_build/html (README.md is its front page), warnings
## as errors; tests/test_docs_site.py builds it too, in `make test`
docs: $(VENV)/.installed-docs
	$(BIN)/sphinx-build -W --keep-going -c docs -b html . docs/_build/html

clean:
	rm -rf $(VENV) robot-arm-out .pytest_cache .ruff_cache .mypy_cache .hypothesis docs/_build docs/api.rst docs/generated docs/gallery docs/_gallery_src
