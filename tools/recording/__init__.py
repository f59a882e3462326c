"""Recordings of the bus (MCAP): record, replay, re-run, evidence (docs/recording.md)."""
