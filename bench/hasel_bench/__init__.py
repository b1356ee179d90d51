"""hasel_bench: the benchmarks and test oracles of the HASEL toolkit, kept out of the product.

- :mod:`hasel_bench.figures`: ``hasel bench`` / ``make bench`` (the table of figures);
  :mod:`~hasel_bench.graph`, :mod:`~hasel_bench.realtime`, :mod:`~hasel_bench.offline`,
  :mod:`~hasel_bench.iospeed`, :mod:`~hasel_bench.fuzz`: its measurements.
- :mod:`hasel_bench.harness`: the blind check's harness (unlabelled case files, each
  diagnosed in a spawned process that sees only the file), used by
  :mod:`~hasel_bench.blind` (cases from the project's own effect library) and
  :mod:`~hasel_bench.othersim` (an independent simulator): together the diagnosis's
  tuning corpus. The untuned verification corpus is ``bench/verify`` (scripts).

Installed into the workspace's venv by ``tools/setup.sh`` (``pip install -e bench``);
the modules that build node graphs need the ROS workspace (run them through ``hasel``).
"""
