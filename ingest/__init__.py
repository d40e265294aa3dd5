"""navreplay ingest: every foreign log format <-> the canonical Parquet tables.

Only this package imports mcap, rosbags, pymavlink, pyulog or a RINEX reader; everything
downstream reads canonical tables (see ``ingest.schema``).
"""
