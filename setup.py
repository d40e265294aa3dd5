"""The package list for setuptools; everything else is in pyproject.toml.

The repository's folders ``pipeline/`` and ``ingest/`` install as ``navreplay.pipeline`` and
``navreplay.ingest`` (``[tool.setuptools] package-dir`` maps the two names to the folders), so
that a wheel puts only ``navreplay`` into site-packages. Setuptools' ``packages.find`` cannot
prefix the names it finds, hence this file: every package under the two folders, named as
installed. ``navreplay`` itself is a namespace package (no ``__init__.py``).
"""

from setuptools import find_packages, setup

FOLDERS = ("pipeline", "ingest")

setup(
    packages=[
        f"navreplay.{name}"
        for name in find_packages(include=[p for f in FOLDERS for p in (f, f"{f}.*")])
    ],
)
