"""Experiments of the papers: pure functions from tables and params to tables and figures."""
