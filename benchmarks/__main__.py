"""`python -m benchmarks [NAME ...]`: run the benchmarks and print their ratio tables."""

from __future__ import annotations

import sys


def main(argv: list[str]) -> int:
    print("no benchmarks are registered yet", file=sys.stderr)
    return 1 if argv else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
