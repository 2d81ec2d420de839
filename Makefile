# Set-up and everyday commands. Everything runs inside .venv, built with Python 3.12 (pymc 6 and
# arviz 1.x need >= 3.12). Override the interpreter with `make PYTHON=/path/to/python3.12 ...`.

PYTHON ?= $(shell for p in python3.12 python3.13 $$HOME/.pyenv/versions/3.12*/bin/python3.12 \
             /usr/local/bin/python3.12 /usr/bin/python3.12 python3; do \
             $$p -c 'import sys; sys.exit(sys.version_info[:2] < (3, 12))' >/dev/null 2>&1 \
             && { echo $$p; break; }; done)
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
DEMO_MAP ?= data/maps/ubremen-cartesium.yaml
DEMO_OUT ?= out/demo

.PHONY: install test test-fast demo bench clean

$(STAMP): pyproject.toml
	@test -n "$(PYTHON)" || { echo "make: no Python >= 3.12 found (set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	@touch $(STAMP)

install: $(STAMP)

# everything (CI: .ci/run): the unit tests, the doctests and the CLI / whole-run tests
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2

# the unit tests and the doctests, without the whole-map runs and the slow statistical tests
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 -m "not slow" tests/unit semmap_pp

demo: $(STAMP)
	$(BIN)/semmap info $(DEMO_MAP)
	$(BIN)/semmap map $(DEMO_MAP) --out $(DEMO_OUT) --force
	@echo "semantic map written to $(DEMO_OUT)/ (open $(DEMO_OUT)/report.html)"

bench: $(STAMP)
	@for b in bench/bench_*.py; do n=$$(basename $$b .py); n=$${n#bench_}; \
	  if [ "$$n" = against ]; then \
	    if [ -z "$(AGAINST)" ]; then echo "== against: skipped (make bench AGAINST=REV times each map against REV)"; continue; fi; \
	    echo "== against $(AGAINST)"; $(BIN)/python bench/run.py against --rev "$(AGAINST)" --json || exit 1; continue; \
	  fi; \
	  echo "== $$n"; $(BIN)/python bench/run.py $$n --json || exit 1; done

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
