"""`python -m benchmarks [NAME ...] [options]`: run the benchmarks and print their ratio tables.

Every module ``benchmarks/bench_<name>.py`` is a benchmark. It defines ``run(options)`` that
prints its own side-by-side table (ours vs the reference, in the same run), and optionally
declares its options, prefixed with the benchmark name, as a list ``OPTIONS`` of
``benchmarks._options.Option`` or adds them in ``add_arguments(parser)``. Adding a
benchmark is adding a module; nothing here changes.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import time
from types import ModuleType

import benchmarks


def discover() -> dict[str, ModuleType]:
    """Benchmark name -> module, for every ``bench_*.py`` in this package."""
    found: dict[str, ModuleType] = {}
    for info in pkgutil.iter_modules(benchmarks.__path__):
        if info.name.startswith("bench_"):
            found[info.name.removeprefix("bench_")] = importlib.import_module(
                f"benchmarks.{info.name}"
            )
    return dict(sorted(found.items()))


def main(argv: list[str]) -> int:
    registry = discover()
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("names", nargs="*", metavar="NAME", help=f"of: {', '.join(registry)}")
    for module in registry.values():
        for option in getattr(module, "OPTIONS", ()):
            option.add_to(parser)
        if hasattr(module, "add_arguments"):
            module.add_arguments(parser)
    options = parser.parse_args(argv)
    unknown = [n for n in options.names if n not in registry]
    if unknown:
        parser.error(f"unknown benchmark(s) {', '.join(unknown)}; known: {', '.join(registry)}")
    for name in options.names or list(registry):
        start = time.perf_counter()
        print(f"== {name}: {(registry[name].__doc__ or '').strip().splitlines()[0]}", flush=True)
        registry[name].run(options)
        print(f"   ({time.perf_counter() - start:.1f} s)\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
