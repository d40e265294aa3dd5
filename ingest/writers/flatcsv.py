"""Any navreplay Parquet table as a flat CSV that PlotJuggler, a spreadsheet or pandas opens.

PlotJuggler's CSV loader takes the first row as the series names and lets the user pick one
numeric column as the time axis; this writer puts that column first: ``time_s``, the row's
``t_ns`` in seconds on the table's time base (float64: sub-microsecond at GPS epochs of today),
followed by the table's columns as they are (``t_ns`` kept as an integer). The header row is
unquoted; a null is an empty cell, NaN is ``nan``; text cells (a stream name, a log message)
are quoted. The Parquet files themselves are flat too: PlotJuggler's Parquet loader
opens them directly (choose ``t_ns`` as the time axis there).

The file is written atomically, in row blocks, so a large run never sits in memory as text.
"""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from navreplay.ingest.atomic import atomic_path

TIME_COLUMN = "time_s"


def with_time_s(table: pa.Table) -> pa.Table:
    """``table`` with ``time_s`` (``t_ns`` / 1e9) as its first column."""
    seconds = pc.divide(pc.cast(table.column("t_ns"), pa.float64(), safe=False), 1e9)
    return table.add_column(0, TIME_COLUMN, seconds)


def write_flat_csv(source: Path, target: Path, *, block_rows: int = 65_536) -> int:
    """Write the Parquet table ``source`` as a flat CSV at ``target``; returns the rows."""
    parquet = pq.ParquetFile(source)
    if "t_ns" not in parquet.schema_arrow.names:
        raise ValueError(f"{source}: no t_ns column: not a navreplay table or run output")
    rows = 0
    no_header = pacsv.WriteOptions(include_header=False)
    with atomic_path(target) as tmp, tmp.open("wb") as sink:
        names = [TIME_COLUMN, *parquet.schema_arrow.names]  # identifiers: written unquoted
        sink.write((",".join(names) + "\n").encode())
        for batch in parquet.iter_batches(batch_size=block_rows):
            block = with_time_s(pa.Table.from_batches([batch]))
            pacsv.write_csv(block, sink, write_options=no_header)
            rows += block.num_rows
    return rows
