# The HASEL toolkit workspace. Two commands matter: `make demo` and `make test`.
SHELL := /bin/bash
VENV := .venv
HASEL := $(VENV)/bin/hasel
PYTEST_ARGS ?=

.PHONY: setup demo test bench clean

setup:
	@bash tools/setup.sh

demo: setup
	$(HASEL) demo

test: setup
	$(HASEL) env -- $(VENV)/bin/python -m pytest -q $(PYTEST_ARGS) src/tests test

bench: setup
	$(HASEL) bench

clean:
	rm -rf build install log out
