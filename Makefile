# gearte: `make demo` and `make test` set themselves up in a local virtualenv.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
OUT    ?= out

.PHONY: demo test lint bench clean help

help:
	@echo "make demo   - set up .venv, run three planetary studies (Wang et al. 2013) and compare them, report in $(OUT)/comparison/"
	@echo "make test   - set up .venv, check lint (ruff) and types (basedpyright), run the whole test suite (notebooks included)"
	@echo "make bench  - run the benchmarks, tables in benchmarks/results/"

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "gearte needs Python >= 3.11 (found %s); set PYTHON=python3.11 or newer" % sys.version.split()[0])'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gearte run examples/planetary_wang2013_random.toml --out $(OUT)/random
	$(BIN)/gearte run examples/planetary_wang2013_rayleigh_allocated.toml --out $(OUT)/allocated
	$(BIN)/gearte run examples/planetary_wang2013_rayleigh_random.toml --out $(OUT)/rayleigh_random
	$(BIN)/gearte compare $(OUT)/random $(OUT)/rayleigh_random $(OUT)/allocated --out $(OUT)/comparison
	@echo
	@echo "Demo finished. Open $(OUT)/comparison/report.md (plots beside it);"
	@echo "each study's own report is $(OUT)/<study>/report.md."
	@echo "To run gearte yourself: . $(VENV)/bin/activate (or call $(BIN)/gearte)."

lint: $(STAMP)
	$(BIN)/ruff check gearte tests benchmarks
	$(BIN)/ruff format --check gearte tests benchmarks
	$(BIN)/basedpyright --level error

test: lint
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_planetary_mc.py
	$(BIN)/python benchmarks/bench_scaleout.py
	$(BIN)/python benchmarks/bench_extrema.py
	$(BIN)/python benchmarks/bench_grid_drives.py
	$(BIN)/python benchmarks/bench_helical.py
	$(BIN)/python benchmarks/bench_rv.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
