"""Dataset and summary reports: self-contained HTML pages with their tables and figures."""
