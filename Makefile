# The README's two commands are `make demo` and `make test`. Each does its own
# set-up on a fresh machine: it creates .venv and installs the project the
# first time (and again when pyproject.toml changes) -- the demo with no
# extras at all, the tests with their test, dev and plot extras.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
RUN_STAMP := $(VENV)/.installed-run-stamp
PKGS   := serialsocket tcpstream linksim

.PHONY: demo docs test test-long lint typecheck pytest fuzz fuzz-install soak bench bench-codec bench-goodput bench-pty bench-latency bench-flood clean

$(RUN_STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $(RUN_STAMP)

$(STAMP): $(RUN_STAMP)
	$(PY) -m pip install --quiet -e '.[test,dev,plot]'
	touch $(STAMP)

demo: $(RUN_STAMP)
	$(PY) -m linksim demo $(ARGS)

# The API reference with the README's tour and the protocol documents, built
# into build/site (open build/site/index.html).  The build itself needs no
# network; any warning fails it (mkdocs.yml: strict).
DOCS_STAMP := $(VENV)/.installed-docs-stamp

$(DOCS_STAMP): $(RUN_STAMP)
	$(PY) -m pip install --quiet -e '.[docs]'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(VENV)/bin/mkdocs build --strict

test: lint typecheck pytest

lint: $(STAMP)
	$(VENV)/bin/ruff check $(PKGS) tests fuzz examples
	$(VENV)/bin/ruff format --check $(PKGS) tests fuzz examples

typecheck: $(STAMP)
	$(VENV)/bin/mypy --strict $(PKGS)

# Two pytest processes at once, one per core: the serial-socket tests (Kermit
# interop through relays, pty transfers) and everything else take about the
# same time, and one process after the other took 14 minutes.  The serial
# socket's report is printed after the other's; the exit status is either's
# failure.
pytest: $(STAMP)
	@$(PY) -m pytest -q tests/serialsocket > .pytest-serialsocket.log 2>&1 & pid=$$!; \
	$(PY) -m pytest -q --ignore=tests/serialsocket; rest=$$?; \
	wait $$pid; ss=$$?; echo "== tests/serialsocket =="; cat .pytest-serialsocket.log; \
	exit $$(( rest != 0 || ss != 0 ))

# Deterministic checks too long for the default run (minutes each): trio's
# stream conformance over the Mars preset.
test-long: $(STAMP)
	$(PY) -m pytest -q -m long --timeout 900

# `make fuzz` runs the hypothesis property fuzzers, then each coverage-guided
# atheris harness for FUZZ_SECONDS (default 60; the issue-11 runs used 600),
# growing its corpus under fuzz/corpus/<harness>/.  A finding stops the run and
# leaves crash-* in that folder; pin it as a regression test.
FUZZ_SECONDS ?= 60
HARNESSES    := fuzz_parser fuzz_arq_receive fuzz_command_packet fuzz_session

fuzz-install: $(STAMP)
	$(PY) -m pip install --quiet -e '.[fuzz]'

fuzz: fuzz-install
	HYPOTHESIS_PROFILE=deep $(PY) -m pytest -q fuzz
	@for h in $(HARNESSES); do \
	  echo "== $$h ($(FUZZ_SECONDS) s)"; \
	  mkdir -p fuzz/corpus/$$h; \
	  log=$${TMPDIR:-/tmp}/telelink-$$h.log; \
	  timeout $$(( $(FUZZ_SECONDS) + 120 )) $(PY) -m fuzz.$$h -max_total_time=$(FUZZ_SECONDS) \
	    -print_final_stats=1 -artifact_prefix=fuzz/corpus/$$h/ fuzz/corpus/$$h >$$log 2>&1; \
	  rc=$$?; grep -v '^"' $$log | grep -v 'INFO: Instrumenting' | tail -15; \
	  [ $$rc -eq 0 ] || { echo "$$h failed (exit $$rc): see $$log"; exit $$rc; }; \
	done

# 24 simulated hours of demo traffic and bulk data over noisy-moon with outages
# (virtual clock).  SOAK_HOURS shortens or lengthens it.
SOAK_HOURS ?= 24

soak: $(STAMP)
	$(PY) -m linksim soak --hours $(SOAK_HOURS)

# Benchmarks measure speed; they are not tests.  `make bench` runs the quick ones.
bench: bench-codec bench-pty bench-latency bench-flood
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

bench-flood: $(STAMP)
	$(PY) -m linksim bench flood

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache .hypothesis
