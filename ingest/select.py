"""Which stream fills which canonical table: automatic by message type, overridden by
``dataset.yaml``.

For each table:

1. ``<table>.topic`` in the descriptor names the stream (a ROS topic, a MAVLink/DataFlash
   message, a ULog topic, ``csv:<table>``); it must exist in the logs and be decodable.
   ``truth`` and ``estimator`` share a schema, so a truth-like stream may fill either.
2. Otherwise the candidates are the streams whose reader says they feed the table. With
   ``<table>.instance``: when the reader declares sensor instances (``StreamInfo.instance``:
   autopilot logs), the candidate of that instance with the most messages; otherwise the
   n-th candidate by stream key. Without it, the candidate with the most messages (ties:
   the key containing ``truth`` for the truth table, then the first key alphabetically).
   The alternatives are reported.
3. The same key in several files of one drive (a split bag) is one stream, read file after
   file in order of first timestamp.
4. ``gnss`` may also get a velocity companion (streams with role ``velocity``, or
   ``gnss.velocity_topic``) whose columns are joined to the fixes by time.

A table listed in ``required`` that gets no stream is E-FATAL naming it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from navreplay.ingest.config import DatasetConfig
from navreplay.ingest.errors import ConfigError, IngestError
from navreplay.ingest.readers.base import Inventory, StreamInfo
from navreplay.ingest.schema import TableName

_TWINS = {TableName.TRUTH, TableName.ESTIMATOR}


@dataclass(frozen=True)
class Source:
    """One file's part of a selected stream."""

    file_index: int
    stream: StreamInfo


@dataclass(frozen=True)
class TablePlan:
    """The stream chosen for a table and why.

    Attributes:
        companion: a stream whose columns are joined to this one's rows by time (the GNSS
            velocity of the fixes), or None.
    """

    table: TableName
    key: str
    sources: tuple[Source, ...]
    reason: str
    alternatives: tuple[str, ...] = ()
    companion: TablePlan | None = None

    @property
    def count(self) -> int | None:
        counts = [s.stream.count for s in self.sources]
        return None if any(c is None for c in counts) else sum(c for c in counts if c is not None)


def _override(config: DatasetConfig | None, table: TableName) -> tuple[str | None, int | None]:
    if config is None:
        return None, None
    section = getattr(config, table.value)
    return getattr(section, "topic", None), getattr(section, "instance", None)


def select_streams(
    inventories: Sequence[Inventory],
    config: DatasetConfig | None,
    *,
    check_required: bool = True,
) -> dict[TableName, TablePlan]:
    """Choose a stream per table (see the module docstring); ``check_required=False`` lets
    ``--list`` show a selection that still lacks a required table.

    Raises:
        ConfigError: a configured topic is absent, not decodable, or for another table.
        IngestError: a required table gets no stream.
    """
    plans: dict[TableName, TablePlan] = {}
    for table in TableName:
        topic, instance = _override(config, table)
        plan = (
            _configured(inventories, table, topic) if topic else _auto(inventories, table, instance)
        )
        if plan is not None and table == TableName.GNSS:
            plan = _with_velocity(inventories, plan, config)
        if plan is not None:
            plans[table] = plan
    for name in config.required if config and check_required else ():
        if TableName(name) not in plans:
            topic, _ = _override(config, TableName(name))
            what = f"topic {topic!r}" if topic else f"no stream that can fill the {name} table"
            raise IngestError(
                f"required table {name!r} has {what} in the logs",
                path=inventories[0].path if inventories else None,
                hint="check `navreplay ingest --list` and the dataset.yaml topics",
            )
    return plans


def _sources(inventories: Sequence[Inventory], key: str) -> tuple[Source, ...]:
    found = [Source(i, s) for i, inv in enumerate(inventories) for s in inv.streams if s.key == key]
    big = 1 << 62
    return tuple(sorted(found, key=lambda s: (s.stream.start_ns or big, s.file_index)))


def _configured(inventories: Sequence[Inventory], table: TableName, topic: str) -> TablePlan:
    sources = _sources(inventories, topic)
    if not sources:
        known = sorted({s.key for inv in inventories for s in inv.streams})
        raise ConfigError(
            f"{table.value}.topic {topic!r} is not in the logs (streams: {', '.join(known)})",
            hint="fix the topic in dataset.yaml; `navreplay ingest --list` shows the streams",
        )
    stream = sources[0].stream
    if stream.role:
        raise ConfigError(
            f"{table.value}.topic {topic!r} is a {stream.role} stream, not the table's main one",
            hint=f"name it as {table.value}.{stream.role}_topic in dataset.yaml",
        )
    fits = stream.table == table or (stream.table in _TWINS and table in _TWINS)
    if not fits:
        why = stream.detail if stream.table is None else f"it feeds {stream.table.value}"
        raise ConfigError(
            f"{table.value}.topic {topic!r} ({stream.msgtype}) cannot fill the {table.value} "
            f"table: {why}"
        )
    return TablePlan(table, topic, sources, f"dataset.yaml {table.value}.topic")


def _candidates(inventories: Sequence[Inventory], table: TableName, role: str) -> dict[str, int]:
    counts: dict[str, int] = {}
    for inv in inventories:
        for s in inv.streams:
            if s.table == table and s.role == role:
                counts[s.key] = counts.get(s.key, 0) + (s.count or 0)
    return counts


def _with_velocity(
    inventories: Sequence[Inventory], plan: TablePlan, config: DatasetConfig | None
) -> TablePlan:
    topic = config.gnss.velocity_topic if config is not None else None
    if topic:
        sources = _sources(inventories, topic)
        if not sources or sources[0].stream.role != "velocity":
            what = "not in the logs" if not sources else "not a velocity stream"
            raise ConfigError(f"gnss.velocity_topic {topic!r} is {what}")
        reason = "dataset.yaml gnss.velocity_topic"
    else:
        counts = _candidates(inventories, TableName.GNSS, "velocity")
        if not counts:
            return plan
        topic = min(counts, key=lambda k: (-counts[k], k))
        sources = _sources(inventories, topic)
        reason = "automatic: GNSS velocity stream"
    companion = TablePlan(TableName.GNSS, topic, sources, reason)
    return TablePlan(plan.table, plan.key, plan.sources, plan.reason, plan.alternatives, companion)


def _instances(inventories: Sequence[Inventory], table: TableName) -> dict[str, int]:
    """Stream key -> sensor instance, for the table's candidates that declare one."""
    return {
        s.key: s.instance
        for inv in inventories
        for s in inv.streams
        if s.table == table and not s.role and s.instance is not None
    }


def _auto(
    inventories: Sequence[Inventory], table: TableName, instance: int | None
) -> TablePlan | None:
    counts = _candidates(inventories, table, "")
    if not counts:
        return None
    keys = sorted(counts)
    declared = _instances(inventories, table)
    if instance is not None and declared:
        # Readers that know sensor instances (autopilot logs) declare them: instance n is the
        # n-th sensor, whichever messages carry it (RAW_IMU and SCALED_IMU are both IMU 0).
        chosen = [k for k in keys if declared.get(k) == instance]
        if not chosen:
            have = ", ".join(f"{k} ({declared.get(k)})" for k in keys)
            raise ConfigError(
                f"{table.value}.instance {instance} requested, the logs have {table.value} "
                f"streams of instances: {have}"
            )
        key = min(chosen, key=lambda k: (-counts[k], k))
        reason = f"dataset.yaml {table.value}.instance {instance} (sensor instance)"
    elif instance is not None:
        if not 0 <= instance < len(keys):
            raise ConfigError(
                f"{table.value}.instance {instance} requested, the logs have {len(keys)} "
                f"{table.value} streams: {', '.join(keys)}"
            )
        key = keys[instance]
        reason = f"dataset.yaml {table.value}.instance {instance}"
    else:
        key = min(
            keys,
            key=lambda k: (-counts[k], not (table == TableName.TRUTH and "truth" in k.lower()), k),
        )
        reason = "automatic: the only candidate" if len(keys) == 1 else "automatic: most messages"
    return TablePlan(
        table,
        key,
        _sources(inventories, key),
        reason,
        tuple(k for k in keys if k != key),
    )
