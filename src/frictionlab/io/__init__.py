"""Files: the run logs (.csv with a JSON sidecar, .dat, Parquet) written by the
simulator and the real-time logger, and read back (docs/logs.md)."""
