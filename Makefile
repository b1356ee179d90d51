# The HASEL toolkit workspace. Two commands matter: `make demo` and `make test`.
SHELL := /bin/bash
VENV := .venv
HASEL := $(VENV)/bin/hasel
PYTEST_ARGS ?=

.PHONY: setup demo test bench clean core-without-ros

setup:
	@bash tools/setup.sh

demo: setup
	$(HASEL) demo

test: setup core-without-ros
	$(HASEL) env -- $(VENV)/bin/python -m pytest -q $(PYTEST_ARGS) src/tests test

# The core library in a venv that has no ros-* package at all: it must import and run.
core-without-ros:
	@bash tools/check_core_without_ros.sh

bench: setup
	OPENBLAS_NUM_THREADS=1 $(HASEL) bench

clean:
	rm -rf build install log out
