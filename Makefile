# The README's two commands are `make demo` and `make test`. Each does its own
# set-up on a fresh machine: it creates .venv and installs the project with its
# test and dev extras the first time (and again when pyproject.toml changes).

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
PKGS   := serialsocket tcpstream linksim

.PHONY: demo test lint typecheck pytest fuzz bench bench-codec bench-goodput bench-pty bench-latency clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,dev,plot]'
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m linksim demo $(ARGS)

test: lint typecheck pytest

lint: $(STAMP)
	$(VENV)/bin/ruff check $(PKGS) tests fuzz examples
	$(VENV)/bin/ruff format --check $(PKGS) tests fuzz examples

typecheck: $(STAMP)
	$(VENV)/bin/mypy --strict $(PKGS)

pytest: $(STAMP)
	$(PY) -m pytest -q

fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=deep $(PY) -m pytest -q fuzz

# Benchmarks measure speed; they are not tests.  `make bench` runs the quick ones.
bench: bench-codec bench-pty bench-latency
	$(PY) -m linksim bench goodput --quick

bench-codec: $(STAMP)
	$(PY) -m linksim bench codec

bench-goodput: $(STAMP)
	$(PY) -m linksim bench goodput --output bench/results/goodput.json \
	  --plot-delay bench/results/goodput-delay.png --plot-ber bench/results/goodput-ber.png

bench-pty: $(STAMP)
	$(PY) -m linksim bench pty

bench-latency: $(STAMP)
	$(PY) -m linksim bench latency

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache .hypothesis
