"""The run log: its format (topics, records, schemas), the recorder that writes it as MCAP, and
the reader that every review goes through (the triad the mcap library itself has).

Here, not in `recorder`, are the two names every side agrees on: the recorder writes there, `log
latest` looks there, and `--log-dir`'s default names it; importing them costs `choreo --help`
nothing (the recorder loads the mcap library)."""

LOG_DIR = "runs"  # where a run or a replay writes its log unless told otherwise
LOG_SUFFIX = ".mcap"  # a log's file name ends so; a review of a folder reads only these
