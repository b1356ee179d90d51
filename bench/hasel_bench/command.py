"""``hasel bench``, declared for the core's command line (entry point ``hasel.commands: bench``)."""
from __future__ import annotations

from hasel.cli import Command

__all__ = ["BENCH"]

BENCH = Command("bench", "the benchmarks that `make bench` runs: one table of ratios, and JSON",
                "hasel_bench.figures:add_arguments", "hasel_bench.figures:run", True)
