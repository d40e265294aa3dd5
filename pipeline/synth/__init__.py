"""Synthesized datasets with exact truth, written as real log files (issue 3)."""
