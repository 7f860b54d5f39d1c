"""The run file: one owner of its schema, writer, reader and repair (docs/run-file.md).

``bench`` writes runs with :class:`RunWriter`; everything reads them with :func:`open_run` (one :class:`Run`
class, live refresh included) or, for an analysis, through :func:`hilbench.analysis.record.load_record`.
"""

from hilbench.common.runfile.schema import (
    AXES,
    CHANNELS,
    DEVICE_CHANNELS,
    EVENT_DTYPE,
    EVENT_KINDS,
    EVENT_MESSAGE_BYTES,
    FINAL_STATUSES,
    LINEAR_ALIASES,
    MAX_CHUNK,
    MAX_SAMPLES,
    RECORDS,
    REQUIRED_CHANNELS,
    RESERVE_BYTES,
    SAMPLE_KINDS,
    SAMPLE_TIMES_KEY,
    SCHEMA,
    SCHEMA_VERSION,
    SCHEMA_VERSIONS,
    STATUSES,
    TIMINGS,
    TORQUE_TIMING,
    TORQUE_TIMINGS,
    ChannelSpec,
    RunFileError,
    check_size,
    host_sampled,
    record_kind,
    run_torque_timing,
    torque_timing_for,
)
from hilbench.common.runfile.store import (
    Run,
    RunWriter,
    channel_summary,
    check_not_truncated,
    clear_write_flags,
    lock_path,
    lookup3,
    open_run,
    repair,
    software_versions,
    utc_now,
    writer_alive,
)

__all__ = [
    "AXES", "CHANNELS", "DEVICE_CHANNELS", "EVENT_DTYPE", "EVENT_KINDS", "EVENT_MESSAGE_BYTES", "FINAL_STATUSES",
    "LINEAR_ALIASES", "MAX_CHUNK", "MAX_SAMPLES", "RECORDS", "REQUIRED_CHANNELS", "RESERVE_BYTES", "SAMPLE_KINDS",
    "SAMPLE_TIMES_KEY", "SCHEMA", "SCHEMA_VERSION", "SCHEMA_VERSIONS", "STATUSES", "TIMINGS", "TORQUE_TIMING",
    "TORQUE_TIMINGS", "ChannelSpec", "Run", "RunFileError", "RunWriter", "channel_summary", "check_not_truncated",
    "check_size", "clear_write_flags", "host_sampled", "lock_path", "lookup3", "open_run", "record_kind", "repair",
    "run_torque_timing", "software_versions", "torque_timing_for", "utc_now", "writer_alive",
]
