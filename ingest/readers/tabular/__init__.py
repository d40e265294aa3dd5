"""Readers of tabular logs: delimited text (CSV) and NumPy array segments (comma2k19)."""
