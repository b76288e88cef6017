"""The MCAP log format's reading and writing: files, chunks, indexes, following a growing log."""
