"""Sinks of the offline stages: summary JSON, derived MCAP log, Rerun recording."""
