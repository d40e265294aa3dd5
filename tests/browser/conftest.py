"""The browser tests reuse the report tests' dataset (real runs through the real writers)."""

from tests.pipeline.report.conftest import dataset_dir

__all__ = ["dataset_dir"]
