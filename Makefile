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

# Tests run in parallel (pytest-xdist, one worker per core up to 8, each file on one worker, each worker in
# its own ROS domain), then the few that assert on wall-clock timing run alone, so no neighbour starves them.
TEST_JOBS ?= $(shell n=$$(nproc 2>/dev/null || echo 2); [ "$$n" -gt 8 ] && n=8; echo $$n)

# (pytest's exit code 5, no test selected, is not a failure: PYTEST_ARGS="-k ..." may pick from one part only)
test: setup core-without-ros
	$(HASEL) env -- $(VENV)/bin/python -m pytest -q -n $(TEST_JOBS) --dist loadfile -m "not wallclock" \
		$(PYTEST_ARGS) src/tests test || [ $$? -eq 5 ]
	$(HASEL) env -- $(VENV)/bin/python -m pytest -q -m wallclock $(PYTEST_ARGS) test || [ $$? -eq 5 ]

# The core library in a venv that has no ros-* package at all: it must import and run.
core-without-ros:
	@bash tools/check_core_without_ros.sh

bench: setup
	OPENBLAS_NUM_THREADS=1 $(HASEL) bench

clean:
	rm -rf build install log out
